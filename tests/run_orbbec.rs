//! `hitl run --camera orbbec...` on the embedded stub with the Orbbec SDK double
//! (`tests/orbbec_fake`, a stand-in libOrbbecSDK.so whose cameras keep their sync configuration
//! in files, as a camera keeps it across processes): the camera is left as found after a
//! completed run, a tripped run and Ctrl-C (SIGINT); a killed run leaves its state file, which
//! `hitl probe` reports and the next run notices and repairs; several cameras need a serial.
//! Runs are serialised: each drives a real-time loop and a physics thread.

mod common;
mod orbbec_fake;

use common::SHARED_VM_LAB;
use hitl_trajectories::{npz, Trajectory};
use orbbec_fake::{FakeOrbbec, FACTORY_SYNC};
use std::path::{Path, PathBuf};
use std::process::{Child, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A 3 s sweep of joint 1 from the stub's power-up pose, a capture every second (software
/// triggered: the SDK double answers each with a frameset).
fn trajectory(dir: &Path) -> PathBuf {
    const HOME: [f64; 7] = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];
    let n = 31;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.1).collect();
    let qpos = t
        .iter()
        .map(|&t| {
            let mut q = HOME;
            q[0] = -0.2 * (std::f64::consts::PI * t / 3.0).sin().powi(2);
            q
        })
        .collect();
    let traj = Trajectory {
        qpos,
        capture: Some((0..n).map(|i| i % 10 == 0).collect()),
        t,
        ..Default::default()
    };
    let path = dir.join("sweep.npz");
    npz::save(&path, &traj, false).expect("write the trajectory");
    path
}

fn run_args<'a>(traj: &'a Path, camera: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "run",
        traj.to_str().expect("utf-8"),
        "--camera",
        camera,
        "--camera-size",
        "64x40",
        "--light",
        "none",
        "--plain",
        "--config",
        SHARED_VM_LAB,
    ];
    args.extend_from_slice(extra);
    args
}

fn spawn(fake: &FakeOrbbec, args: &[&str]) -> Child {
    fake.hitl()
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start hitl run")
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// Wait until the SDK double has taken `n` software triggers (the loop is playing).
fn wait_for_triggers(fake: &FakeOrbbec, child: &mut Child, n: usize) {
    let end = Instant::now() + Duration::from_secs(60);
    while fake.log().matches("trigger CP").count() < n {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("hitl run ended early ({status}); log:\n{}", fake.log());
        }
        assert!(Instant::now() < end, "no trigger within 60 s; log:\n{}", fake.log());
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn ctrl_c_ends_the_run_with_the_camera_as_found() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80")]);
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = trajectory(dir.path());
    let mut child = spawn(&fake, &run_args(&traj, "orbbec:software", &[]));
    wait_for_triggers(&fake, &mut child, 1);
    // While it plays, the camera is changed and the state file says what it had.
    assert_eq!(fake.sync("CP1"), "32 0 0 0 0 0 1", "software triggering, trigger out off");
    assert!(fake.marker("CP1").exists(), "state file while the camera is changed");
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill -INT");
    assert!(sent.success());
    let out = child.wait_with_output().expect("wait");
    assert_eq!(out.status.code(), Some(130), "{}", text(&out));
    assert_eq!(fake.sync("CP1"), FACTORY_SYNC, "written back; log:\n{}", fake.log());
    assert!(!fake.marker("CP1").exists(), "state file removed");
    let log = fake.log();
    let stop = log.rfind("stop CP1").expect("streams stopped");
    assert!(log[stop..].contains("sync CP1 1 out 1"), "written back after the stop:\n{log}");
}

#[test]
fn a_tripped_run_leaves_the_named_camera_as_found_and_the_other_untouched() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80"), ("CP2", 0x0840, "1.0.80")]);
    fake.set_sync("CP2", "1 0 0 0 0 0 1"); // trigger out off: written back as found
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = trajectory(dir.path());
    let mcap = dir.path().join("run.mcap");
    let m = mcap.to_str().expect("utf-8");
    let args =
        run_args(&traj, "orbbec:software@CP2", &["--stub-fault", "estop@1.5", "--record", m]);
    let out = fake.hitl().args(&args).stdin(Stdio::null()).output().expect("run");
    assert_eq!(out.status.code(), Some(4), "{}", text(&out));
    // The captures before the trip carry the colour lens the SDK double reports (Brown-Conrady
    // k1 0.125, k2 -0.25, p1 0.001, p2 -0.002).
    let want = [0.125, -0.25, f64::from(0.001f32), f64::from(-0.002f32), 0.0];
    let mut lenses = 0;
    hitl_record::reader::visit(
        &mcap,
        |msg| {
            if msg.topic == "/camera/calibration" {
                let (_, k) = hitl_record::reader::decode_intrinsics(msg.data, msg.log_time)
                    .expect("intrinsics");
                assert_eq!(k.distortion.d(), &want[..]);
                lenses += 1;
            }
            std::ops::ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .expect("the recording reads");
    assert!(lenses >= 1, "no capture recorded before the trip:\n{}", text(&out));
    assert_eq!(fake.sync("CP2"), "1 0 0 0 0 0 1", "log:\n{}", fake.log());
    assert!(fake.log().contains("sync CP2 32 out 0"), "it was triggered:\n{}", fake.log());
    assert!(!fake.log().contains("sync CP1"), "the other camera untouched:\n{}", fake.log());
    assert!(!fake.marker("CP2").exists());
}

#[test]
fn several_cameras_and_none_named_is_exit_2_listing_them() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80"), ("CP2", 0x0842, "1.0.80")]);
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = trajectory(dir.path());
    let out = fake
        .hitl()
        .args(run_args(&traj, "orbbec:software", &[]))
        .stdin(Stdio::null())
        .output()
        .expect("run");
    let all = text(&out);
    assert_eq!(out.status.code(), Some(2), "{all}");
    assert!(
        all.contains("2 Orbbec cameras are connected (serials CP1, CP2): name one with --camera orbbec@SERIAL"),
        "{all}"
    );
    assert_eq!((fake.sync("CP1"), fake.sync("CP2")), (FACTORY_SYNC.into(), FACTORY_SYNC.into()));
}

#[test]
fn a_killed_run_is_reported_by_probe_and_repaired_by_the_next_run() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80")]);
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = trajectory(dir.path());
    let mut child = spawn(&fake, &run_args(&traj, "orbbec:software", &[]));
    wait_for_triggers(&fake, &mut child, 1);
    child.kill().expect("SIGKILL");
    let _ = child.wait();
    assert_eq!(fake.sync("CP1"), "32 0 0 0 0 0 1", "left in software triggering");
    assert!(fake.marker("CP1").exists(), "the state file stays");

    let out = fake.hitl().args(["probe", "--camera"]).stdin(Stdio::null()).output().expect("probe");
    let all = text(&out);
    assert!(all.contains("sync mode found: software-triggering"), "{all}");
    assert!(
        all.contains("LEFTOVER: a run ended without writing the camera's configuration back"),
        "{all}"
    );

    let out = fake
        .hitl()
        .args(run_args(&traj, "orbbec:software", &[]))
        .stdin(Stdio::null())
        .output()
        .expect("run");
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("warning: Orbbec camera CP1: a run ended without writing"), "{all}");
    assert_eq!(fake.sync("CP1"), FACTORY_SYNC, "the configuration from before the killed run");
    assert!(!fake.marker("CP1").exists());
}
