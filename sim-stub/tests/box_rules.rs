//! The stub's box holds to what a real control box enforces (docs/xarm-protocol.md): its serial
//! number picks the joint-limit table; motion enable, clean error, set brake and set mode are
//! system resets (no motion until set_state(0)); servo_j moves the arm only in mode 1 and state
//! 1/2; joint-limit, speed and TCP-speed errors; warning 13 for unknown registers; and the
//! command port takes at most 250 commands per second, so an over-fast stream backs up.

mod protocol_common;

use hitl_drivers::xarm::codes;
use hitl_drivers::xarm::registers::{self as reg, arm_state, mode};
use hitl_drivers::xarm::{ClientConfig, ServoReplies, XarmClient, XarmError};
use hitl_hal::{Arm, Joints};
use hitl_sim_stub::server::arm_box::{ArmBox, BoxIdentityConfig, BoxReply};
use hitl_sim_stub::{Stub, StubConfig};
use hitl_trajectories::joint_table::JointTable;
use protocol_common::LagPlant;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

const Q0: Joints = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];

fn boxed(limits: [(f64, f64); 7]) -> ArmBox {
    ArmBox::new(Box::new(LagPlant::new(None)), Q0, limits, BoxIdentityConfig::default())
}

fn current() -> ArmBox {
    boxed(JointTable::Xarm7Current.limits())
}

fn servo_params(q: &Joints) -> [u8; 40] {
    let mut p = [0u8; 40];
    for (j, v) in q.iter().enumerate() {
        p[4 * j..4 * j + 4].copy_from_slice(&(*v as f32).to_le_bytes());
    }
    p
}

/// clean_error, clean_warn, motion_enable, set_mode(1), set_state(0) at time `t`.
fn enable(b: &mut ArmBox, t: f64) {
    b.handle(reg::CLEAN_ERR, &[], t);
    b.handle(reg::CLEAN_WAR, &[], t);
    b.handle(reg::MOTION_EN, &[8, 1], t);
    b.handle(reg::SET_MODE, &[mode::SERVO, 0], t);
    b.handle(reg::SET_STATE, &[arm_state::START], t);
}

/// One servo_j at `t`, then 20 ms of physics.
fn servo(b: &mut ArmBox, q: &Joints, t: f64) -> BoxReply {
    let r = b.handle(reg::MOVE_SERVOJ, &servo_params(q), t);
    for _ in 0..10 {
        b.step(0.002);
    }
    r
}

/// How far the arm is from Q0 (f32 rounding of a Q0 setpoint stays under 1e-6).
fn moved(b: &ArmBox) -> f64 {
    b.plant_joints().iter().zip(Q0.iter()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max)
}

#[test]
fn the_default_stub_is_a_current_xarm7_and_enforces_its_table() {
    let config = StubConfig::default();
    let sn = &config.identity.arm_sn;
    let digits: u32 = sn[2..6].parse().expect("digits [2:6]");
    assert!((1305..=8499).contains(&digits), "{sn}");
    assert_eq!(config.effective_joint_limits(), JointTable::Xarm7Current.limits());
    let legacy = StubConfig::default().with_serial("XS1303HITL01");
    assert_eq!(legacy.effective_joint_limits(), JointTable::Xarm7Legacy.limits());
    assert_eq!(legacy.identity.box_sn, "XX1303HITL01");
    let mut bad = StubConfig::ephemeral();
    bad.identity.firmware = "2.5".into();
    assert!(Stub::start(bad, Box::new(LagPlant::new(None))).is_err());
    for sn in ["XS 1305,x", "XS1305HITL000001"] {
        let bad = StubConfig::ephemeral().with_serial(sn);
        assert!(Stub::start(bad, Box::new(LagPlant::new(None))).is_err(), "{sn}");
    }

    // J4 at -0.15 rad: inside the first arms' table, beyond a current arm's (-0.10472).
    let mut q = Q0;
    q[3] = 0.0;
    let mut b = current();
    b.plant_mut().reset(&q);
    b.handle(reg::SET_STATE, &[4], 0.0);
    enable(&mut b, 0.0);
    q[3] = -0.05;
    let mut t = 0.0;
    while q[3] > -0.15 {
        t += 0.02;
        let r = servo(&mut b, &q, t);
        if r.state != 0 {
            break;
        }
        q[3] -= 0.02;
    }
    assert_eq!(b.status().error_code, codes::ERR_JOINT_LIMIT, "J4 {}", q[3]);
    assert!(q[3] < -0.10472 && q[3] > -0.10472 - 0.021, "refused at {}", q[3]);
    assert_eq!(b.status().state, arm_state::STOPPED);
}

#[test]
fn system_resets_stop_motion_until_set_state_0() {
    let mut q1 = Q0;
    q1[0] += 0.01;
    for (name, register, params) in [
        ("motion_enable", reg::MOTION_EN, &[8u8, 1][..]),
        ("clean_error", reg::CLEAN_ERR, &[][..]),
        ("set_brake", reg::SET_BRAKE, &[8, 1][..]),
        ("set_mode", reg::SET_MODE, &[mode::SERVO, 0][..]),
        ("set_state(4)", reg::SET_STATE, &[4][..]),
    ] {
        let mut b = current();
        enable(&mut b, 0.0);
        assert_eq!(servo(&mut b, &Q0, 0.1).state, 0, "{name}: ready before");
        let r = b.handle(register, params, 0.2);
        assert_eq!(r.state & reg::STATE_INVALID, 0, "{name} accepted");
        assert_eq!(b.status().state, arm_state::STOPPED, "{name} stops the arm");
        let r = servo(&mut b, &q1, 0.3);
        assert_eq!(r.state, reg::STATE_NOT_READY, "{name}: servo_j answered not ready");
        assert!(moved(&b) < 1e-6, "{name}: servo_j must not move the arm");
        b.handle(reg::SET_STATE, &[arm_state::START], 0.4);
        assert_eq!(servo(&mut b, &q1, 0.5).state, 0, "{name}: moves again after set_state(0)");
        assert!(moved(&b) > 1e-3, "{name}");
    }
    // clean_warn is no system reset (register 17).
    let mut b = current();
    enable(&mut b, 0.0);
    b.handle(reg::CLEAN_WAR, &[], 0.1);
    assert_eq!(servo(&mut b, &q1, 0.2).state, 0);
    // set_mode(1) after set_state(0): stopped; servo_j does nothing until set_state(0).
    let mut b = current();
    b.handle(reg::MOTION_EN, &[8, 1], 0.0);
    b.handle(reg::SET_STATE, &[arm_state::START], 0.0);
    b.handle(reg::SET_MODE, &[mode::SERVO], 0.1);
    assert_eq!(
        b.status(),
        hitl_sim_stub::server::arm_box::BoxStatus {
            enabled: true,
            state: arm_state::STOPPED,
            mode: mode::SERVO,
            error_code: 0,
            warn_code: 0,
        }
    );
    assert_eq!(servo(&mut b, &q1, 0.2).state, reg::STATE_NOT_READY);
    assert!(moved(&b) < 1e-6);
    // servo_j in mode 0, or paused: refused without moving.
    let mut b = current();
    enable(&mut b, 0.0);
    b.handle(reg::SET_MODE, &[mode::POSITION], 0.0);
    b.handle(reg::SET_STATE, &[arm_state::START], 0.0);
    servo(&mut b, &q1, 0.1);
    assert!(moved(&b) < 1e-6, "servo_j in mode 0");
    let mut b = current();
    enable(&mut b, 0.0);
    b.handle(reg::SET_STATE, &[arm_state::PAUSED], 0.0);
    assert_eq!(servo(&mut b, &q1, 0.1).state, reg::STATE_NOT_READY);
    assert!(moved(&b) < 1e-6, "servo_j while paused");
}

#[test]
fn speed_errors_come_from_the_firmware_limits() {
    // Joint speed (24): a step of 0.02 rad in 4 ms is 5 rad/s > 180 deg/s; 0.012 rad is not.
    let mut b = current();
    enable(&mut b, 0.0);
    let mut q = Q0;
    q[6] += 0.012;
    assert_eq!(servo(&mut b, &q, 1.000).state, 0);
    q[6] += 0.012;
    assert_eq!(servo(&mut b, &q, 1.004).state, 0, "3 rad/s is inside the limit");
    q[6] += 0.02;
    let r = servo(&mut b, &q, 1.008);
    assert_eq!(r.state & reg::STATE_ERROR, reg::STATE_ERROR);
    assert_eq!(b.status().error_code, codes::ERR_SPEED_LIMIT);
    assert_eq!(b.status().state, arm_state::STOPPED);

    // The first setpoint after set_state(0) is taken over 50 ms at most: a 0.2 rad jump is 4 rad/s.
    let mut b = current();
    enable(&mut b, 0.0);
    let mut q = Q0;
    q[0] += 0.2;
    servo(&mut b, &q, 5.0);
    assert_eq!(b.status().error_code, codes::ERR_SPEED_LIMIT);

    // TCP linear speed in servo_j (60): the arm stretched out (flange about 0.47 m from the
    // base axis), joint 1 at 3 rad/s (under 180 deg/s) swings the flange at about 1.4 m/s.
    const QS: Joints = [0.0, 0.8, 0.0, 1.0, 0.0, 0.2, 0.0];
    let stretched = |firmware: &str| {
        let identity = BoxIdentityConfig { firmware: firmware.into(), ..Default::default() };
        let limits = JointTable::Xarm7Current.limits();
        let mut b = ArmBox::new(Box::new(LagPlant::new(None)), QS, limits, identity);
        enable(&mut b, 0.0);
        assert_eq!(servo(&mut b, &QS, 0.996).state, 0);
        b
    };
    let mut q = QS;
    q[0] += 0.012;
    let mut b = stretched("v2.5.0");
    servo(&mut b, &q, 1.000);
    assert_eq!(b.status().error_code, codes::ERR_SERVOJ_LINEAR_SPEED);
    // The same step with a firmware before 2.3.0 (no error 60): accepted.
    let mut b = stretched("v2.2.0");
    assert_eq!(servo(&mut b, &q, 1.000).state, 0);
    assert_eq!(b.status().error_code, 0);

    // Feedback speed (30): the joints measured faster than 180 deg/s.
    let mut b = current();
    enable(&mut b, 0.0);
    b.plant_mut().command(&[3.0; 7]); // behind the box's back: the plant races away
    b.step(0.002);
    assert_eq!(b.status().error_code, codes::ERR_FEEDBACK_SPEED);
}

#[test]
fn unknown_registers_and_bad_parameters() {
    let mut b = current();
    let r = b.handle(200, &[], 0.0);
    assert_eq!(r.state & reg::STATE_INVALID, reg::STATE_INVALID);
    assert_eq!(r.state & reg::STATE_WARNING, reg::STATE_WARNING);
    assert_eq!(b.status().warn_code, codes::WARN_NO_SUCH_COMMAND);
    assert_eq!(b.unknown_registers, vec![200]);
    b.handle(reg::CLEAN_WAR, &[], 0.0);
    assert_eq!(b.status().warn_code, 0);
    for (register, params) in [
        (reg::MOTION_EN, &[9u8, 1][..]),
        (reg::MOTION_EN, &[8, 2][..]),
        (reg::SET_STATE, &[7][..]),
        (reg::SET_MODE, &[12][..]),
        (reg::SET_MODE, &[2][..]),
        (reg::MOVE_SERVOJ, &[0; 28][..]),
    ] {
        let r = b.handle(register, params, 0.0);
        assert_eq!(r.state & reg::STATE_INVALID, reg::STATE_INVALID, "{register} {params:?}");
    }
}

fn stub_client(max_outstanding: u32) -> (hitl_sim_stub::StubHandle, XarmClient) {
    let config = StubConfig { initial_q: Q0, ..StubConfig::ephemeral() };
    let stub = Stub::start(config, Box::new(LagPlant::new(None))).expect("stub");
    let config = ClientConfig {
        servo_replies: ServoReplies::Pipelined { max_outstanding },
        ..ClientConfig::default()
    };
    let mut arm = XarmClient::connect(stub.cmd_addr(), config).expect("connects");
    arm.enable_servo().expect("enables");
    (stub, arm)
}

#[test]
fn the_command_port_takes_at_most_250_per_second_and_a_faster_stream_backs_up() {
    // A flood: every setpoint the link takes, 0.6 s long, then every reply.
    let (stub, mut arm) = stub_client(1000);
    let before = stub.with_box(|b| b.servo_commands);
    let t = Instant::now();
    let mut sent = 0;
    while t.elapsed() < Duration::from_millis(600) {
        arm.servo_joint(&Q0).expect("taken");
        sent += 1;
        if arm.outstanding() > 200 {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    arm.flush_servo_replies().expect("all answered");
    let rate = (stub.with_box(|b| b.servo_commands) - before) as f64 / t.elapsed().as_secs_f64();
    eprintln!("flood: {sent} setpoints, served {rate:.1} per second");
    assert!(rate <= 252.0 && rate > 150.0, "served {rate:.1}/s");
    stub.shutdown();

    // 1000 Hz with the controller's interlock (25 unanswered at most): the backlog trips it.
    let (stub, mut arm) = stub_client(25);
    let t = Instant::now();
    let err = loop {
        if let Err(e) = arm.servo_joint(&Q0) {
            break e;
        }
        assert!(t.elapsed() < Duration::from_secs(2), "an over-fast stream must back up");
        std::thread::sleep(Duration::from_millis(1));
    };
    assert!(matches!(err, XarmError::Backlog(25)), "{err}");
    eprintln!("1000 Hz stream tripped after {:?}", t.elapsed());
    stub.shutdown();
}

#[test]
fn a_250_hz_stream_on_absolute_deadlines_keeps_up() {
    // What the controller's loop does: one setpoint per 4 ms tick on absolute deadlines, 3 s.
    let (stub, mut arm) = stub_client(25);
    let c = stub.counters();
    let before = c.commands.load(Relaxed);
    let start = Instant::now();
    let mut max_outstanding = 0;
    for i in 1..=750u32 {
        let deadline = start + Duration::from_micros(4000 * u64::from(i));
        if let Some(d) = deadline.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        let mut q = Q0;
        q[0] += 0.1 * (f64::from(i) * 0.004).sin();
        arm.servo_joint(&q).expect("taken");
        max_outstanding = max_outstanding.max(arm.outstanding());
    }
    arm.flush_servo_replies().expect("all answered");
    let served = c.commands.load(Relaxed) - before;
    let paced = c.paced_commands.load(Relaxed);
    let wait_ms = c.max_pace_wait_ns.load(Relaxed) as f64 * 1e-6;
    eprintln!(
        "250 Hz: {served} commands, {paced} waited for their slot, longest wait {wait_ms:.2} ms, \
         at most {max_outstanding} replies outstanding (the interlock allows 25)"
    );
    assert_eq!(served, 750);
    assert!(max_outstanding < 25, "{max_outstanding} outstanding");
    assert_eq!(stub.status().error_code, 0);
    stub.shutdown();
}

#[test]
fn stop_does_not_wait_for_its_reply() {
    let (stub, mut arm) = stub_client(25);
    let t = Instant::now();
    arm.stop().expect("written");
    let took = t.elapsed();
    assert_eq!(arm.outstanding(), 1, "the stop's reply is outstanding");
    assert!(took < Duration::from_millis(3), "stop took {took:?}");
    arm.flush_servo_replies().expect("the stop's reply arrives and is discarded");
    assert_eq!(arm.outstanding(), 0);
    assert_eq!(arm.state().expect("state"), arm_state::STOPPED);
    assert_eq!(stub.status().state, arm_state::STOPPED);
    // Identity on connect still works.
    assert_eq!(arm.serial_number().expect("sn"), StubConfig::default().identity.arm_sn);
    assert!(arm.version().expect("version").ends_with(",v2.5.0"));
    stub.shutdown();
}
