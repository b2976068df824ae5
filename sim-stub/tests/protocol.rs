//! The project's own xArm client against the stub: connect, enable, stream servo_j, read back
//! through get_joint_pos and the report stream; joint-limit and collision errors; faults;
//! garbage on the command port. Uses a first-order test plant (no physics engine).

mod protocol_common;

use hitl_drivers::xarm::codes;
use hitl_drivers::xarm::report::ReportKind;
use hitl_drivers::xarm::{
    ClientConfig, ReportConfig, ReportReader, ServoReplies, XarmClient, XarmError,
};
use hitl_hal::{Arm, ArmReports, Error, ErrorKind, Inputs, Joints};
use hitl_sim_stub::{FaultKind, Stub, StubConfig, StubError, StubHandle};
use protocol_common::LagPlant;
use std::io::{Read, Write};
use std::time::Duration;

const Q0: Joints = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];
const Q1: Joints = [0.3, -0.3, 0.2, 1.1, -0.2, 1.2, 0.4];

fn start(wall: Option<(usize, f64)>) -> StubHandle {
    let config = StubConfig { initial_q: Q0, ..StubConfig::ephemeral() };
    Stub::start(config, Box::new(LagPlant::new(wall))).expect("stub starts on loopback")
}

fn client(stub: &StubHandle) -> XarmClient {
    XarmClient::connect(stub.cmd_addr(), ClientConfig::default()).expect("connects")
}

fn reader(stub: &StubHandle) -> ReportReader {
    let (host, config) = stub.report_config(ReportConfig::default());
    assert_eq!(config.port, stub.report_addr(ReportKind::Real).map(|a| a.port()));
    assert_eq!(config.codes_port, stub.report_addr(ReportKind::Normal).map(|a| a.port()));
    ReportReader::connect(host, config).expect("report port connects")
}

/// Stream a straight line from `from` to `to` in `steps` servo_j setpoints at 250 Hz.
fn stream(arm: &mut XarmClient, from: &Joints, to: &Joints, steps: usize) -> Result<(), XarmError> {
    for i in 1..=steps {
        let s = i as f64 / steps as f64;
        let mut q = *from;
        for j in 0..7 {
            q[j] += (to[j] - from[j]) * s;
        }
        arm.servo_joint(&q)?;
        std::thread::sleep(Duration::from_millis(4));
    }
    arm.flush_servo_replies()
}

fn assert_close(a: &Joints, b: &Joints, tol: f64) {
    for j in 0..7 {
        assert!(
            (a[j] - b[j]).abs() < tol,
            "joint {}: {} vs {} (all: {a:?} vs {b:?})",
            j + 1,
            a[j],
            b[j]
        );
    }
}

/// Skip reports until one stamped after `settle`.
fn fresh_report(r: &mut ReportReader, settle: Duration) -> hitl_hal::ArmState {
    let until = std::time::Instant::now() + settle;
    loop {
        let s = r.next_report().expect("report arrives");
        if std::time::Instant::now() >= until {
            return s;
        }
    }
}

#[test]
fn rust_client_streams_servo_j_and_reads_back_the_pose() {
    let stub = start(None);
    let mut arm = client(&stub);
    assert!(arm.version().expect("version").ends_with("v2.5.0"));
    assert_eq!(arm.serial_number().expect("sn"), "XS1305HITL01");
    let mut reports = reader(&stub);
    let first = reports.next_report().expect("first report");
    assert_eq!(first.state, 4, "a box at power-up is stopped");
    arm.enable_servo().expect("enables");
    let s = stub.status();
    assert!(s.enabled);
    assert_eq!((s.mode, s.error_code), (1, 0));
    assert_close(&arm.joint_positions().expect("joints"), &Q0, 1e-5);

    stream(&mut arm, &Q0, &Q1, 200).expect("stream accepted");
    assert_eq!(arm.servo_sent(), 200);
    std::thread::sleep(Duration::from_millis(300));
    assert_close(&arm.joint_positions().expect("joints"), &Q1, 1e-3);
    let r = fresh_report(&mut reports, Duration::from_millis(50));
    assert_close(&r.q, &Q1, 1e-3);
    assert_eq!((r.mode, r.error_code, r.warn_code), (1, 0, 0));
    assert_eq!(r.state, 2, "settled arm is ready, not moving");
    let r2 = reports.next_report().expect("next report");
    assert_eq!(r2.seq, r.seq + 1);
    assert!(r2.received_ns > r.received_ns);
    assert_eq!(stub.with_box(|b| b.unknown_registers.clone()), Vec::<u8>::new());

    arm.stop().expect("stop");
    assert_eq!(arm.state().expect("state"), 4);
    // A stopped box refuses servo setpoints: the next call reports it.
    let _ = arm.servo_joint(&Q0);
    let err = arm.flush_servo_replies().expect_err("stopped arm refuses servo_j");
    assert_eq!(err.kind(), ErrorKind::DeviceFault, "{err}");
    stub.shutdown();
}

#[test]
fn joint_limit_violation_raises_error_23() {
    let stub = start(None);
    let mut arm = client(&stub);
    let mut reports = reader(&stub);
    arm.enable_servo().expect("enables");
    let mut beyond = Q0;
    beyond[1] = 2.2; // joint 2 upper limit 2.094 rad
    arm.servo_joint(&beyond).expect("written");
    let err = arm.flush_servo_replies().expect_err("box refuses");
    assert!(matches!(err, XarmError::ArmFault { .. }), "{err}");
    assert_eq!(arm.codes().expect("codes"), (codes::ERR_JOINT_LIMIT, 0));
    assert_eq!(arm.state().expect("state"), 4);
    assert_close(&stub.plant_joints(), &Q0, 1e-3);
    let r = fresh_report(&mut reports, Duration::from_millis(300));
    assert_eq!((r.state, r.error_code), (4, codes::ERR_JOINT_LIMIT));
    // Clearing and re-enabling brings the arm back.
    arm.enable_servo().expect("re-enables after clean_error");
    assert_eq!(arm.codes().expect("codes"), (0, 0));
    stream(&mut arm, &Q0, &Q1, 50).expect("streams again");
    stub.shutdown();
}

#[test]
fn collision_with_the_scene_raises_error_31() {
    let stub = start(Some((0, 0.2)));
    let mut arm = client(&stub);
    arm.enable_servo().expect("enables");
    let result = stream(&mut arm, &Q0, &Q1, 150);
    assert!(result.is_err(), "the stream must be refused after the collision");
    assert_eq!(arm.codes().expect("codes"), (codes::ERR_COLLISION, 0));
    assert_eq!(stub.status().state, 4);
    let c = stub.with_box(|b| b.last_collision.clone()).expect("collision recorded");
    assert_eq!(c.other, "enclosure wall");
    assert!(stub.plant_joints()[0] <= 0.2 + 1e-9);
    stub.shutdown();
}

#[test]
fn faults_deviation_estop_door_and_drop() {
    let stub = start(None);
    let mut arm = client(&stub);
    arm.enable_servo().expect("enables");
    stub.inject(FaultKind::Deviation(0.05));
    let q = arm.joint_positions().expect("joints");
    let truth = stub.plant_joints();
    for j in 0..7 {
        assert!((q[j] - truth[j] - 0.05).abs() < 1e-5);
    }
    let mut inputs = stub.inputs();
    assert!(!inputs.read().expect("reads").door_open);
    stub.inject(FaultKind::DoorOpen);
    assert!(inputs.read().expect("reads").door_open);
    stub.inject(FaultKind::Estop);
    assert!(inputs.read().expect("reads").estop_pressed);
    assert_eq!(arm.codes().expect("codes"), (codes::ERR_ESTOP_IO, 0));
    arm.clean_error().expect("answers");
    assert_eq!(arm.codes().expect("codes").0, codes::ERR_ESTOP_IO, "held e-stop cannot be cleared");
    let err = arm.enable_servo().expect_err("cannot enable under e-stop");
    assert_eq!(err.kind(), ErrorKind::DeviceFault);

    stub.inject(FaultKind::DropConnection);
    // The stub closes within its poll period; allow a loaded machine some slack.
    let deadline = std::time::Instant::now() + Duration::from_secs(3);
    let err = loop {
        match arm.codes() {
            Err(e) => break e,
            Ok(_) if std::time::Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(20))
            }
            Ok(_) => panic!("the stub kept the connection after drop-connection"),
        }
    };
    assert!(matches!(err.kind(), ErrorKind::Disconnected), "{err}");
    // New connections are served.
    let mut again = client(&stub);
    assert_eq!(again.codes().expect("codes").0, codes::ERR_ESTOP_IO);
    stub.shutdown();
}

#[test]
fn stalled_reports_time_out_the_reader_and_arm_error_shows_up() {
    let stub = start(None);
    let mut reports = reader(&stub);
    reports.next_report().expect("reports flow");
    stub.inject(FaultKind::ArmError(24));
    let r = fresh_report(&mut reports, Duration::from_millis(300));
    assert_eq!((r.state, r.error_code), (4, 24));
    stub.inject(FaultKind::StallReports(None));
    std::thread::sleep(Duration::from_millis(30));
    let err = loop {
        match reports.next_report() {
            Ok(_) => continue,
            Err(e) => break e,
        }
    };
    assert_eq!(err.kind(), ErrorKind::Timeout, "{err}");
    stub.shutdown();
}

#[test]
fn stalled_replies_fail_the_setpoint_after_the_allowed_backlog_and_then_recover() {
    let stub = start(None);
    let config = ClientConfig {
        servo_replies: ServoReplies::Pipelined { max_outstanding: 10 },
        ..ClientConfig::default()
    };
    let mut arm = XarmClient::connect(stub.cmd_addr(), config).expect("connects");
    arm.enable_servo().expect("enables");
    stream(&mut arm, &Q0, &Q0, 5).expect("answered while the box hears");

    // One second: far longer than sending eleven setpoints takes, even on a VM that loses its
    // vCPUs for a while, so the stall cannot end before the backlog fills.
    stub.inject(FaultKind::StallReplies(Some(1.0)));
    std::thread::sleep(Duration::from_millis(20));
    let mut sent = 0;
    let err = loop {
        match arm.servo_joint(&Q0) {
            Ok(()) => sent += 1,
            Err(e) => break e,
        }
        assert!(sent <= 10, "the eleventh unanswered setpoint must fail");
    };
    assert_eq!(sent, 10, "ten setpoints may await their replies");
    assert!(matches!(err, XarmError::Backlog(10)), "{err}");
    assert_eq!(err.kind(), ErrorKind::Timeout);

    // The stall ends: the late replies arrive and the stream goes on.
    std::thread::sleep(Duration::from_millis(1100));
    arm.flush_servo_replies().expect("the late replies arrive");
    stream(&mut arm, &Q0, &Q0, 5).expect("answered again");
    stub.shutdown();
}

#[test]
fn garbage_on_the_command_port_closes_only_that_connection() {
    let stub = start(None);
    let mut raw = std::net::TcpStream::connect(stub.cmd_addr()).expect("connects");
    raw.write_all(&[0xde, 0xad, 0xbe, 0xef, 0xff, 0xff, 0x01, 0x02]).expect("writes");
    raw.set_read_timeout(Some(Duration::from_secs(2))).expect("timeout");
    let mut buf = [0u8; 16];
    assert_eq!(raw.read(&mut buf).expect("closed cleanly"), 0, "stub must close on garbage");
    let mut arm = client(&stub);
    assert_eq!(arm.codes().expect("still serves"), (0, 0));
    assert!(stub.counters().bad_frames.load(std::sync::atomic::Ordering::Relaxed) >= 1);
    stub.shutdown();
}

#[test]
fn refuses_a_non_loopback_bind() {
    let config = StubConfig { bind: "0.0.0.0".parse().expect("ip"), ..StubConfig::ephemeral() };
    match Stub::start(config, Box::new(LagPlant::new(None))) {
        Err(StubError::NotLoopback(_)) => {}
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("must refuse 0.0.0.0 without allow_remote"),
    }
}

#[test]
fn rust_client_against_the_mujoco_stub_reads_back_and_hits_the_wall() {
    use hitl_sim_stub::mujoco_plant::MujocoPlant;
    use hitl_trajectories::lab::LabConfig;
    use std::f64::consts::{FRAC_PI_2, PI};
    // Arm stretched out horizontally towards the far end (the plant's own wall scenario).
    let start_q = [PI, 1.4167, 0.0, 2.81, 0.0, 0.5467, 0.0];
    let plant = MujocoPlant::new(&LabConfig::default(), None).expect("MuJoCo lab plant");
    let config = StubConfig { initial_q: start_q, ..StubConfig::ephemeral() };
    let stub = Stub::start(config, Box::new(plant)).expect("stub starts");
    let mut arm = client(&stub);
    let mut reports = reader(&stub);
    arm.enable_servo().expect("enables");
    let mut q1 = start_q;
    q1[0] += 0.2;
    q1[5] += 0.1;
    stream(&mut arm, &start_q, &q1, 150).expect("stream accepted");
    std::thread::sleep(Duration::from_millis(500));
    assert_close(&arm.joint_positions().expect("joints"), &q1, 2e-3);
    let r = fresh_report(&mut reports, Duration::from_millis(50));
    assert_close(&r.q, &q1, 2e-3);
    assert_eq!((r.state, r.mode, r.error_code), (2, 1, 0));
    // Turn joint 1 into the side wall: the box raises error 31 and stops.
    let mut wall = q1;
    wall[0] = PI + FRAC_PI_2;
    assert!(stream(&mut arm, &q1, &wall, 500).is_err(), "the wall must stop the stream");
    assert_eq!(arm.codes().expect("codes"), (codes::ERR_COLLISION, 0));
    let c = stub.with_box(|b| b.last_collision.clone()).expect("collision recorded");
    assert!(c.other.starts_with("wall"), "{c:?}");
    let r = fresh_report(&mut reports, Duration::from_millis(300));
    assert_eq!((r.state, r.error_code), (4, codes::ERR_COLLISION));
    stub.shutdown();
}
