//! Interoperability: the official xArm Python SDK (xarm-python-sdk, from `make setup`) drives the
//! stub with its defaults: connect, clear errors, enable, mode 1, state 0, a servo_j stream, then
//! reads the pose back through get_servo_angle and its report stream; then a joint-limit
//! violation and a collision must show the real error codes (23, 31) to the SDK; then clean,
//! enable and set_mode(1) without set_state(0) (a system reset: servo_j is answered "not ready"
//! and moves nothing), set_state(0) (it moves again), a servo_j step beyond 180 deg/s (error 24)
//! and recovery. The stub answers as a current xArm7, so the SDK applies the current joint table.
//!
//! Run twice: with the MuJoCo lab plant (what `hitl stub` serves) and with a first-order plant.
//! The stub runs on the box's own ports (502, 30000-30003) when they are free (we run as root);
//! otherwise on free ports, with the SDK's port constants set to them by the peer script.

mod protocol_common;

use hitl_drivers::xarm::report::ReportKind;
use hitl_hal::Joints;
use hitl_sim_stub::mujoco_plant::MujocoPlant;
use hitl_sim_stub::plant::Plant;
use hitl_sim_stub::{Stub, StubConfig, StubHandle};
use hitl_trajectories::joint_table::JointTable;
use hitl_trajectories::lab::LabConfig;
use protocol_common::LagPlant;
use serde_json::{json, Value};
use std::f64::consts::{FRAC_PI_2, PI};
use std::process::Command;
use std::sync::Mutex;

const Q0: Joints = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];
const Q1: Joints = [0.3, -0.3, 0.2, 1.1, -0.2, 1.2, 0.4];
/// The test plant's wall: joint 1 cannot pass 0.6 rad.
const WALL: (usize, f64) = (0, 0.6);

/// Both tests want the box's own ports: run them one at a time.
static BOX_PORTS: Mutex<()> = Mutex::new(());

fn start_stub(initial_q: Joints, plant: impl Fn() -> Box<dyn Plant>) -> (StubHandle, bool) {
    let config = StubConfig { initial_q, ..StubConfig::default() };
    match Stub::start(config, plant()) {
        Ok(stub) => (stub, true),
        Err(e) => {
            eprintln!("box ports busy or not bindable ({e}); using free ports");
            let config = StubConfig { initial_q, ..StubConfig::ephemeral() };
            (Stub::start(config, plant()).expect("stub on free ports"), false)
        }
    }
}

fn port(stub: &StubHandle, kind: ReportKind) -> u16 {
    stub.report_addr(kind).expect("served").port()
}

fn joints(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect()
}

fn assert_close(got: &[f64], want: &Joints, tol: f64, what: &str) {
    assert_eq!(got.len(), 7, "{what}: {got:?}");
    for j in 0..7 {
        assert!(
            (got[j] - want[j]).abs() < tol,
            "{what}: joint {} {} vs {}",
            j + 1,
            got[j],
            want[j]
        );
    }
}

/// Start a stub around `plant`, run the SDK peer, check everything it saw.
fn sdk_session(
    plant: impl Fn() -> Box<dyn Plant>,
    q0: Joints,
    q1: Joints,
    collide_q: Joints,
    tol: f64,
) {
    let python = env!("HITL_VENV_PYTHON");
    assert!(
        std::path::Path::new(python).exists(),
        "no Python venv at {python}: run make setup (it installs xarm-python-sdk)"
    );
    let _ports = BOX_PORTS.lock().unwrap_or_else(|e| e.into_inner());
    let (stub, on_box_ports) = start_stub(q0, plant);
    if on_box_ports {
        assert_eq!(stub.cmd_addr().port(), 502);
    }
    let mut limit_q = q1;
    // Joint 2 just past a current xArm7's limit, inside the SDK's 0.1 degree tolerance.
    limit_q[1] = JointTable::Xarm7Current.limits()[1].1 + 0.001;
    let args = json!({
        "host": stub.cmd_addr().ip().to_string(),
        "cmd_port": stub.cmd_addr().port(),
        "real_port": port(&stub, ReportKind::Real),
        "normal_port": port(&stub, ReportKind::Normal),
        "rich_port": port(&stub, ReportKind::Rich),
        "realtime_port": port(&stub, ReportKind::RealTime),
        "q0": q0, "q1": q1, "limit_q": limit_q, "collide_q": collide_q,
    });
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/xarm_sdk_peer.py");
    let out = Command::new(python).arg(script).arg(args.to_string()).output().expect("python runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "peer failed: {}\nstdout:\n{stdout}\nstderr:\n{stderr}",
        out.status
    );
    let last = stdout.lines().rev().find(|l| l.starts_with('{')).expect("JSON line");
    let v: Value = serde_json::from_str(last).expect("peer prints JSON");
    let ctx = format!("peer said {v:#}\nstderr:\n{stderr}");

    assert_eq!(v["connected"], true, "{ctx}");
    assert_eq!(v["reported"], true, "{ctx}");
    assert_eq!(v["version_number"], json!([2, 5, 0]), "{ctx}");
    assert_eq!(v["sn"], StubConfig::default().identity.arm_sn.as_str(), "{ctx}");
    assert_eq!(v["enable_codes"], json!([0, 0, 0, 0, 0]), "{ctx}");
    assert_eq!(v["mode_after_enable"], 1, "{ctx}");
    assert_eq!(v["state_after_enable"], 2, "{ctx}");
    assert_eq!(v["servo_codes"], json!([0]), "every servo_j accepted: {ctx}");
    assert_eq!(v["get_servo_angle"]["code"], 0, "{ctx}");
    assert_close(&joints(&v["get_servo_angle"]["angles"]), &q1, tol, "get_servo_angle");
    assert_close(&joints(&v["report_angles"]), &q1, tol, "report stream (30002 via the SDK)");
    assert_close(
        &joints(&v["raw_real"]["angles"]),
        &q1,
        tol,
        "30003 read with the SDK's structure",
    );
    assert_eq!(v["raw_real"]["size"], 135, "{ctx}");
    assert_eq!(v["raw_normal"]["size"], 145, "{ctx}");

    // Joint limit: the box answers the servo_j with its error bit (SDK code 1) and error 23.
    assert_eq!(v["limit"]["servo_code"], 1, "{ctx}");
    assert_eq!(v["limit"]["err_warn"], json!([0, [23, 0]]), "{ctx}");
    assert_eq!(v["limit"]["state"], 4, "{ctx}");
    assert_eq!(v["limit"]["report_error"], 23, "{ctx}");

    // Collision with the scene: error 31 (collision caused abnormal current).
    assert_eq!(v["recover_codes"], json!([0, 0, 0, 0, 0]), "{ctx}");
    assert_eq!(v["collision"]["err_warn"], json!([0, [31, 0]]), "{ctx}");
    assert_eq!(v["collision"]["state"], 4, "{ctx}");
    assert_eq!(v["collision"]["report_error"], 31, "{ctx}");

    // The SDK picked the current table from the serial number: it refuses J4 = -0.15 itself.
    assert_eq!(v["sdk_range_check"], -8, "{ctx}");

    // System reset: clean_error and set_mode leave the arm stopped until set_state(0).
    let seq = &v["reset_sequence"];
    assert_eq!(seq["clean_error"], 0, "{ctx}");
    assert_eq!(seq["state_after_clean"], 4, "{ctx}");
    assert_eq!((&seq["motion_enable"], &seq["set_mode"]), (&json!(0), &json!(0)), "{ctx}");
    assert_eq!(seq["state_after_mode"], 4, "{ctx}");
    assert_eq!(seq["servo_without_state0"], 9, "SDK code 9, not ready: {ctx}");
    let still = seq["moved_without_state0"].as_f64().expect("number");
    assert!(still < 1e-3, "servo_j without set_state(0) moved the arm {still} rad: {ctx}");
    assert_eq!(seq["set_state0"], 0, "{ctx}");
    assert_eq!(seq["state_after_state0"], 2, "{ctx}");
    assert_eq!(seq["servo_after_state0"], json!([0]), "{ctx}");
    let moved = seq["moved_after_state0"].as_f64().expect("number");
    assert!(moved > 0.015, "after set_state(0) the arm follows: {moved} rad: {ctx}");

    // Speed: a 0.3 rad step in one setpoint is error 24, the arm stopped and not moved.
    assert_eq!(seq["speed_servo_code"], 1, "{ctx}");
    assert_eq!(seq["speed_err_warn"], json!([0, [24, 0]]), "{ctx}");
    assert_eq!(seq["speed_state"], 4, "{ctx}");
    assert_eq!(seq["speed_report_error"], 24, "{ctx}");
    assert!(seq["speed_moved_j7"].as_f64().expect("number") < 0.01, "{ctx}");

    // Recovery.
    assert_eq!(seq["recover_codes"], json!([0, 0, 0, 0, 0]), "{ctx}");
    assert_eq!(seq["recovered_state"], 2, "{ctx}");
    assert_eq!(seq["recovered_err_warn"], json!([0, [0, 0]]), "{ctx}");
    assert_eq!(seq["recovered_report_error"], 0, "{ctx}");
    assert_eq!(seq["recovered_servo"], 0, "{ctx}");
    eprintln!("SDK sequence: {seq:#}");

    assert_eq!(stub.with_box(|b| b.unknown_registers.clone()), Vec::<u8>::new(), "{ctx}");
    stub.shutdown();
}

#[test]
fn official_python_sdk_against_the_mujoco_stub() {
    // The generated lab; the arm stretched out horizontally towards the far end, as in the
    // plant's own wall test. A small servo move, then a turn of joint 1 into the side wall.
    let start = [PI, 1.4167, 0.0, 2.81, 0.0, 0.5467, 0.0];
    let mut q1 = start;
    q1[0] += 0.2;
    q1[5] += 0.1;
    let mut collide = start;
    collide[0] = PI + FRAC_PI_2;
    let plant = || -> Box<dyn Plant> {
        Box::new(MujocoPlant::new(&LabConfig::default(), None).expect("MuJoCo lab plant"))
    };
    sdk_session(plant, start, q1, collide, 2e-3);
}

#[test]
fn official_python_sdk_against_a_first_order_plant() {
    let mut collide_q = Q1;
    collide_q[0] = 1.0;
    sdk_session(|| Box::new(LagPlant::new(Some(WALL))), Q0, Q1, collide_q, 1e-3);
}
