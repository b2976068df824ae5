//! What each capture records of the camera's lens and of the light, end to end on the stub: the
//! stub's lab (`--stub-config`) holds a lens distortion the controller's lab does not, the
//! simulated camera announces it as a real camera its factory calibration, and every
//! `/camera/calibration` carries its five numbers; with `[light] lead_ms` each capture's
//! `/camera/sync` holds the level the light was at for that exposure, not the one already sent
//! for the ticks after it.

use hitl_record::reader::{decode_intrinsics, read_recording, visit};
use hitl_trajectories::{npz, Trajectory};
use std::ops::ControlFlow;

mod common;
use common::{hitl, SHARED_VM_LAB};

const HOME: [f64; 7] = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];
const LENS: [f64; 5] = [-0.12, 0.045, 0.0011, -0.0007, -0.006];

/// 0.2 for the first second, 0.6 for the second, 1.0 after.
fn level_at(t: f64) -> f32 {
    if t < 1.0 - 1e-9 {
        0.2
    } else if t < 2.0 - 1e-9 {
        0.6
    } else {
        1.0
    }
}

#[test]
fn every_capture_records_the_lens_and_the_light_level_of_its_exposure() {
    let dir = tempfile::tempdir().expect("tempdir");
    let vm = std::fs::read_to_string(SHARED_VM_LAB).expect("the shared-VM lab");
    // The controller's lab: the light goes 200 ms (50 ticks) early. The stub's: the lens.
    let lab = dir.path().join("lab.toml");
    std::fs::write(&lab, format!("{vm}\n[light]\nlead_ms = 200\n")).expect("lab");
    let stub = dir.path().join("stub.toml");
    std::fs::write(&stub, format!("{vm}\n[camera]\ndistortion = {LENS:?}\n")).expect("stub lab");
    // A 3 s sweep; captures 0.1 s before each change of level (t = 0.9, 1.9, 2.9), where the
    // level sent 200 ms ahead is already the next one.
    let n = 31;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.1).collect();
    let traj = Trajectory {
        qpos: t
            .iter()
            .map(|&t| {
                let mut q = HOME;
                q[0] = -0.2 * (std::f64::consts::PI * t / 3.0).sin().powi(2);
                q
            })
            .collect(),
        capture: Some((0..n).map(|i| i % 10 == 9).collect()),
        light: Some(t.iter().map(|&t| level_at(t)).collect()),
        t,
        ..Default::default()
    };
    let path = dir.path().join("lit.npz");
    npz::save(&path, &traj, false).expect("trajectory");
    let mcap = dir.path().join("run.mcap");
    let (p, m) = (path.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    let (l, s) = (lab.to_str().expect("utf-8"), stub.to_str().expect("utf-8"));
    let run = hitl(&[
        "run",
        p,
        "--record",
        m,
        "--camera",
        "sim",
        "--camera-preset",
        "orbbec",
        "--camera-size",
        "160x100",
        "--light",
        "sim",
        "--plain",
        "--clock",
        "sim",
        "--config",
        l,
        "--stub-config",
        s,
    ]);
    let out =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert_eq!(run.status.code(), Some(0), "{out}");

    // Every calibration message carries the stub's lens, which the controller never read.
    let mut calibrations = 0;
    visit(
        &mcap,
        |msg| {
            if msg.topic == "/camera/calibration" {
                let c = <foxglove::messages::CameraCalibration as prost::Message>::decode(msg.data)
                    .expect("decodes");
                assert_eq!(c.distortion_model, "plumb_bob");
                assert_eq!(c.d, LENS.to_vec(), "D of the capture at {}", msg.log_time);
                let (_, k) = decode_intrinsics(msg.data, msg.log_time).expect("intrinsics");
                assert_eq!(k.distortion.d(), &LENS[..]);
                calibrations += 1;
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .expect("visit");
    assert_eq!(calibrations, 3, "one calibration per capture");
    let rec = read_recording(&mcap).expect("recording");

    // The level of each exposure: the schedule's at the capture, though by then the light had
    // been sent the next level (its change went out 200 ms before the change).
    let levels: Vec<Option<f32>> = rec.capture_sync.iter().map(|s| s.light_level).collect();
    assert_eq!(levels, vec![Some(0.2), Some(0.6), Some(1.0)], "{:?}", rec.capture_sync);
    for s in &rec.capture_sync[..2] {
        let sent = rec.lights.iter().rev().find(|l| l.t_ns <= s.trigger_ns).map(|l| l.level);
        assert_eq!(
            sent.map(|l| l > s.light_level.unwrap_or(1.0)),
            Some(true),
            "the level sent last before the capture is already the next one: {sent:?}"
        );
    }
}
