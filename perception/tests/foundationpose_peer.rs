//! The FoundationPose peer (peers/foundationpose) against a stand-in FoundationPose module with
//! the real one's signatures (peers/foundationpose/tests/stand_in; no CUDA): its Python unit
//! tests, then the `socket:PATH` backend end to end against the peer.
#![allow(clippy::unwrap_used)]

use hitl_hal::Pose;
use hitl_perception::socket::SocketEstimator;
use hitl_perception::testing::{intrinsics_hfov, look_pose, render};
use hitl_perception::{
    EstimateKind, Mesh, PerceptionError, PerceptionFrame, PoseEstimator, TargetModel,
};
use nalgebra::{Rotation3, Vector3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const W: u32 = 48;
const H: u32 = 40;

fn peer_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../peers/foundationpose")
}

fn python() -> &'static str {
    let python = env!("HITL_VENV_PYTHON");
    assert!(Path::new(python).exists(), "{python} missing: run make setup");
    python
}

/// The peer's own tests (session and connection loop against the stand-in).
#[test]
fn the_peers_python_tests_pass() {
    let out = Command::new(python())
        .args(["-m", "unittest", "discover", "-s", "tests", "-t", "."])
        .current_dir(peer_dir())
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "the peer's Python tests failed:\n{text}");
    // unittest prints "Ran N tests": make sure it found them.
    let ran: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("Ran ")?.split_whitespace().next()?.parse().ok())
        .unwrap_or(0);
    assert!(ran >= 10, "only {ran} Python tests ran:\n{text}");
}

/// `python -m hitl_foundationpose` serving the stand-in; killed (and reaped) on drop.
struct Peer {
    child: Child,
    socket: PathBuf,
    log: PathBuf,
    calls: PathBuf,
    dir: tempfile::TempDir,
}

impl Peer {
    fn start() -> Peer {
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("fp.sock");
        let log = dir.path().join("peer.log");
        let calls = dir.path().join("calls.jsonl");
        let child = Command::new(python())
            .args(["-m", "hitl_foundationpose"])
            .arg(&socket)
            .arg("--foundationpose-dir")
            .arg(peer_dir().join("tests/stand_in"))
            .arg("--debug-dir")
            .arg(dir.path().join("debug"))
            .current_dir(peer_dir())
            .env("HITL_FP_STAND_IN_LOG", &calls)
            .env("TMPDIR", dir.path())
            .env("PYTHONDONTWRITEBYTECODE", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        let mut peer = Peer { child, socket, log, calls, dir };
        let deadline = Instant::now() + Duration::from_secs(60);
        while !peer.socket.exists() {
            if let Some(status) = peer.child.try_wait().unwrap() {
                panic!("the peer exited ({status}): {}", peer.log_text());
            }
            assert!(Instant::now() < deadline, "the peer did not listen: {}", peer.log_text());
            std::thread::sleep(Duration::from_millis(20));
        }
        peer
    }

    fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// What the stand-in FoundationPose was called with, in order (register and track_one).
    fn estimator_calls(&self) -> Vec<Value> {
        std::fs::read_to_string(&self.calls)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<Value>(l).unwrap())
            .filter(|c| c["call"] == "register" || c["call"] == "track_one")
            .collect()
    }

    /// Mesh files the stand-in wrote (as FoundationPose does) that are still there.
    fn mesh_files_left(&self) -> usize {
        std::fs::read_dir(self.dir.path())
            .unwrap()
            .filter(|e| {
                e.as_ref().unwrap().file_name().to_string_lossy().starts_with("hitl-fp-stand-in")
            })
            .count()
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn mesh() -> Mesh {
    TargetModel::from_spec("asymmetric").unwrap().lab_mesh(1.0).unwrap()
}

fn frame(seq: u64, range_m: f64) -> PerceptionFrame {
    let k = intrinsics_hfov(W, H, 40.0);
    let mut p: Pose = look_pose(range_m, 0.4, -0.3, 0.9);
    p.translation.x = 0.1;
    let mut f = render(&mesh(), &p, &k, 1_000 + seq);
    f.seq = seq;
    f
}

/// The target pixels' depths (mask, finite, > 0) and their back-projected centroid, computed
/// here independently of the peer.
fn target(f: &PerceptionFrame) -> (Vec<f64>, Vector3<f64>) {
    let k = &f.intrinsics;
    let mut zs = Vec::new();
    let mut sum = Vector3::zeros();
    for v in 0..k.height as usize {
        for u in 0..k.width as usize {
            let i = v * k.width as usize + u;
            let z = f.depth_m[i] as f64;
            if z.is_finite() && z > 0.0 && f.mask.as_ref().unwrap()[i] != 0 {
                sum += Vector3::new((u as f64 - k.cx) / k.fx * z, (v as f64 - k.cy) / k.fy * z, z);
                zs.push(z);
            }
        }
    }
    assert!(zs.len() > 100, "the test frame should show the target, has {} pixels", zs.len());
    let c = sum / zs.len() as f64;
    (zs, c)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn vec3(v: &Value) -> Vector3<f64> {
    Vector3::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap(), v[2].as_f64().unwrap())
}

#[test]
fn hitl_against_the_peer_registers_tracks_normalises_and_refuses_a_maskless_frame() {
    let peer = Peer::start();
    let mut est = SocketEstimator::connect(&peer.socket, &mesh())
        .unwrap_or_else(|e| panic!("connect: {e}; peer log: {}", peer.log_text()));
    assert!(est.peer_name().starts_with("FoundationPose via hitl_foundationpose"));

    // Non-finite depth on the target must reach FoundationPose as no return.
    let mut f0 = frame(0, 4.0);
    let on_target: Vec<usize> =
        (0..f0.depth_m.len()).filter(|&i| f0.depth_m[i] > 0.0).step_by(50).collect();
    let depth = std::sync::Arc::make_mut(&mut f0.depth_m);
    for (n, &i) in on_target.iter().enumerate() {
        depth[i] = if n % 2 == 0 { f32::NAN } else { f32::INFINITY };
    }
    let frames = [f0, frame(1, 3.0), frame(2, 3.5), frame(4, 2.5)];
    let mut kinds = Vec::new();
    let mut translations = Vec::new();
    let r_fixed = *Rotation3::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians()).matrix();
    for (n, f) in frames.iter().enumerate() {
        if n == 2 {
            est.reset();
        }
        if n == 3 {
            // A frame without a mask is refused; the connection and the track are kept.
            let mut bare = frame(3, 2.5);
            bare.mask = None;
            let msg = match est.estimate(&bare) {
                Err(PerceptionError::External(m)) => m,
                other => panic!("expected an External error, got {other:?}"),
            };
            assert!(msg.contains("frame 3 has no target mask"), "{msg}");
        }
        let e = est.estimate(f).unwrap_or_else(|e| panic!("{e}; peer log: {}", peer.log_text()));
        let p = e.pose.expect("a pose");
        let (_, centroid) = target(f);
        let t = p.translation.vector;
        assert!((t - centroid).norm() < 1e-5 * centroid.norm(), "frame {n}: {t:?} vs {centroid:?}");
        assert!((p.rotation.to_rotation_matrix().into_inner() - r_fixed).norm() < 1e-12);
        kinds.push(e.kind);
        translations.push(t);
    }
    assert_eq!(
        kinds,
        [
            EstimateKind::Registered,
            EstimateKind::Tracked,
            EstimateKind::Registered,
            EstimateKind::Tracked
        ]
    );

    // What the stand-in FoundationPose saw: each call's target at a 1 m median with no
    // non-finite depth, 5 iterations to register and 2 to track; its translation came back
    // multiplied by the frame's median target depth.
    let calls = peer.estimator_calls();
    let names: Vec<&str> = calls.iter().map(|c| c["call"].as_str().unwrap()).collect();
    assert_eq!(names, ["register", "track_one", "register", "track_one"]);
    let iterations: Vec<u64> = calls.iter().map(|c| c["iteration"].as_u64().unwrap()).collect();
    assert_eq!(iterations, [5, 2, 5, 2]);
    for ((c, f), t) in calls.iter().zip(&frames).zip(&translations) {
        assert!((c["median_depth"].as_f64().unwrap() - 1.0).abs() < 1e-6, "{c}");
        assert_eq!(c["nonfinite"], 0, "{c}");
        let k = median(target(f).0);
        assert!(k > 1.5, "the frames are meant to be far from 1 m, k = {k}");
        let back = vec3(&c["returned_t"]) * k;
        assert!((back - t).norm() < 1e-6 * t.norm(), "{back:?} vs {t:?} (k {k})");
    }
    assert_eq!(peer.log_text().matches("accepted").count(), 1, "{}", peer.log_text());
    // FoundationPose's per-mesh files are cleaned up as the mesh is rescaled: one left.
    assert_eq!(peer.mesh_files_left(), 1);
}
