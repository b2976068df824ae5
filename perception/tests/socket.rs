//! The external-estimator backend (`socket:PATH`) against the reference peer
//! scripts/pose_peer.py (the venv's Python and numpy), well-behaved and with each of its faults.
#![allow(clippy::unwrap_used)]

use hitl_hal::Pose;
use hitl_perception::models::Symmetry;
use hitl_perception::socket::{SocketConfig, SocketEstimator};
use hitl_perception::testing::{intrinsics_hfov, look_pose, render};
use hitl_perception::{
    backend_from_spec, BackendSpec, Estimate, EstimateKind, Mesh, PerceptionError, PerceptionFrame,
    PoseEstimator, TargetModel,
};
use nalgebra::{UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const W: u32 = 40;
const H: u32 = 32;

/// A running pose_peer.py; killed (and reaped) on drop.
struct Peer {
    child: Child,
    socket: PathBuf,
    log: PathBuf,
    _dir: tempfile::TempDir,
}

impl Peer {
    fn start(args: &[&str]) -> Peer {
        let python = env!("HITL_VENV_PYTHON");
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/pose_peer.py");
        assert!(Path::new(python).exists(), "{python} missing: run make setup");
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("peer.sock");
        let log = dir.path().join("peer.log");
        let child = Command::new(python)
            .arg(script)
            .arg(&socket)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        let mut peer = Peer { child, socket, log, _dir: dir };
        let deadline = Instant::now() + Duration::from_secs(60);
        while !peer.socket.exists() {
            if let Some(status) = peer.child.try_wait().unwrap() {
                panic!("pose_peer.py {args:?} exited ({status}): {}", peer.log_text());
            }
            assert!(
                Instant::now() < deadline,
                "pose_peer.py {args:?} did not listen within 60 s: {}",
                peer.log_text()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        peer
    }

    /// Connections the peer accepted (from its log; needs a peer started without `--quiet`).
    fn connections(&self) -> usize {
        self.log_text().matches("accepted").count()
    }

    fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn mesh() -> Mesh {
    TargetModel::from_spec("asymmetric").unwrap().lab_mesh(0.2).unwrap()
}

fn gt_pose() -> Pose {
    let mut p = look_pose(0.9, 0.3, -0.4, 1.1);
    p.translation.x = 0.02;
    p.translation.y = -0.01;
    p
}

fn frame(seq: u64) -> PerceptionFrame {
    let k = intrinsics_hfov(W, H, 40.0);
    let mut f = render(&mesh(), &gt_pose(), &k, 1_000 + seq);
    f.seq = seq;
    f
}

/// The centroid of the target pixels back-projected (the reference peer's estimate), computed
/// here independently of the peer.
fn expected_centroid(f: &PerceptionFrame) -> Vector3<f64> {
    let k = &f.intrinsics;
    let mut sum = Vector3::zeros();
    let mut n = 0usize;
    for v in 0..k.height as usize {
        for u in 0..k.width as usize {
            let i = v * k.width as usize + u;
            let z = f.depth_m[i] as f64;
            let in_mask = f.mask.as_ref().is_none_or(|m| m[i] != 0);
            if z.is_finite() && z > 0.0 && in_mask {
                sum += Vector3::new((u as f64 - k.cx) / k.fx * z, (v as f64 - k.cy) / k.fy * z, z);
                n += 1;
            }
        }
    }
    assert!(n > 20, "the test frame should show the target, has {n} pixels");
    sum / n as f64
}

fn assert_centroid_pose(e: &Estimate, f: &PerceptionFrame) {
    let p = e.pose.expect("a pose");
    assert_eq!(p.rotation, UnitQuaternion::identity());
    let t = p.translation.vector;
    let want = expected_centroid(f);
    assert!((t - want).norm() < 1e-9, "translation {t:?}, expected centroid {want:?}");
}

fn connect(peer: &Peer) -> SocketEstimator {
    SocketEstimator::connect(&peer.socket, &mesh())
        .unwrap_or_else(|e| panic!("connect: {e}; peer log: {}", peer.log_text()))
}

/// The error message of an `External` error; panics on `Ok` or another error.
fn external<T>(r: Result<T, PerceptionError>) -> String {
    match r {
        Err(PerceptionError::External(m)) => m,
        Err(e) => panic!("expected an External error, got {e:?}"),
        Ok(_) => panic!("expected an External error, got Ok"),
    }
}

fn assert_mentions(msg: &str, path: &Path, parts: &[&str]) {
    assert!(msg.contains(&path.display().to_string()), "{msg:?} does not name {}", path.display());
    for p in parts {
        assert!(msg.contains(p), "{msg:?} does not mention {p:?}");
    }
}

/// The error of the first frame against a peer with `fault` (the handshake succeeds).
fn frame_fault(fault: &str) -> (String, Peer) {
    let peer = Peer::start(&["--quiet", "--fault", fault]);
    let mut est = connect(&peer);
    let msg = external(est.estimate(&frame(5)));
    assert_mentions(&msg, &peer.socket, &["frame 5"]);
    (msg, peer)
}

#[test]
fn centroid_pose_matches_the_masked_back_projection() {
    let peer = Peer::start(&["--quiet"]);
    let m = mesh();
    let mut est = connect(&peer);
    assert_eq!(est.name(), format!("socket:{}", peer.socket.display()));
    // The peer names what it received: the mesh arrived whole.
    let summary = format!(
        "mesh {} vertices {} triangles size {} m",
        m.vertices().len(),
        m.faces().len(),
        m.greatest_dimension()
    );
    assert!(est.peer_name().contains(&summary), "{:?} lacks {summary:?}", est.peer_name());

    let f = frame(5);
    let e = est.estimate(&f).unwrap();
    assert_eq!(e.kind, EstimateKind::Direct);
    assert_eq!(e.residual_m, 0.0);
    assert_centroid_pose(&e, &f);
    // The centroid is of the visible surface: near, but not at, the true position.
    assert!((e.pose.unwrap().translation.vector - gt_pose().translation.vector).norm() < 0.2);

    // The mask travels and is used: cover the left half and the centroid moves right.
    let mut half = frame(6);
    let mask = std::sync::Arc::make_mut(half.mask.as_mut().unwrap());
    for (i, m) in mask.iter_mut().enumerate() {
        if (i % W as usize) < W as usize / 2 {
            *m = 0;
        }
    }
    let e2 = est.estimate(&half).unwrap();
    assert_centroid_pose(&e2, &half);
    let dx = e2.pose.unwrap().translation.vector.x - e.pose.unwrap().translation.vector.x;
    assert!(dx > 1e-3, "masking the left half should move the centroid right, moved {dx}");

    // No colour and no mask: every valid depth pixel counts (the background has depth 0).
    let mut bare = frame(7);
    bare.color = Vec::new().into();
    bare.mask = None;
    let e3 = est.estimate(&bare).unwrap();
    assert_centroid_pose(&e3, &bare);
    assert!(
        (e3.pose.unwrap().translation.vector - e.pose.unwrap().translation.vector).norm() < 1e-9
    );
}

#[test]
fn an_empty_mask_or_no_depth_is_lost() {
    let peer = Peer::start(&["--quiet"]);
    let mut est = connect(&peer);
    let mut f = frame(3);
    f.mask = Some(vec![0; (W * H) as usize].into());
    let e = est.estimate(&f).unwrap();
    assert_eq!(e.kind, EstimateKind::Lost);
    assert!(e.pose.is_none());
    let mut f = frame(4);
    std::sync::Arc::make_mut(&mut f.depth_m).iter_mut().for_each(|d| *d = 0.0);
    assert_eq!(est.estimate(&f).unwrap().kind, EstimateKind::Lost);
    // And the connection is still good.
    assert_eq!(est.estimate(&frame(5)).unwrap().kind, EstimateKind::Direct);
}

#[test]
fn kind_residual_and_reset_round_trip() {
    let peer = Peer::start(&["--quiet", "--kind", "auto", "--residual", "0.004"]);
    let mut est = connect(&peer);
    let kinds: Vec<EstimateKind> = (0..2).map(|s| est.estimate(&frame(s)).unwrap().kind).collect();
    assert_eq!(kinds, [EstimateKind::Registered, EstimateKind::Tracked]);
    est.reset();
    est.reset(); // two resets in a row send one
    let e = est.estimate(&frame(2)).unwrap();
    assert_eq!(e.kind, EstimateKind::Registered, "the peer did not see the reset");
    assert_eq!(e.residual_m, 0.004);
    assert_eq!(est.estimate(&frame(3)).unwrap().kind, EstimateKind::Tracked);
}

#[test]
fn backend_from_spec_builds_the_socket_backend() {
    let peer = Peer::start(&["--quiet"]);
    let spec: BackendSpec = format!("socket:{}", peer.socket.display()).parse().unwrap();
    assert_eq!(spec, BackendSpec::Socket(peer.socket.clone()));
    let mut est = backend_from_spec(&spec, &mesh(), &Symmetry::none()).unwrap().unwrap();
    assert_eq!(est.name(), format!("socket:{}", peer.socket.display()));
    let f = frame(9);
    assert_centroid_pose(&est.estimate(&f).unwrap(), &f);
}

#[test]
fn a_bad_frame_is_refused_before_the_socket() {
    let peer = Peer::start(&["--quiet"]);
    let mut est = connect(&peer);
    let mut f = frame(1);
    std::sync::Arc::make_mut(&mut f.depth_m).pop();
    assert!(matches!(est.estimate(&f), Err(PerceptionError::BadFrame(_))));
    let f = frame(2);
    assert_centroid_pose(&est.estimate(&f).unwrap(), &f);
}

#[test]
fn nothing_listening_says_start_the_estimator() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("absent.sock");
    let msg = external(SocketEstimator::connect(&missing, &mesh()));
    assert_mentions(&msg, &missing, &["no socket", "start the estimator first"]);
    let msg = external(backend_from_spec(
        &BackendSpec::Socket(missing.clone()),
        &mesh(),
        &Symmetry::none(),
    ));
    assert_mentions(&msg, &missing, &["start the estimator first"]);

    // A socket file left behind by a peer that is gone.
    let stale = dir.path().join("stale.sock");
    drop(std::os::unix::net::UnixListener::bind(&stale).unwrap());
    assert!(stale.exists());
    let msg = external(SocketEstimator::connect(&stale, &mesh()));
    assert_mentions(&msg, &stale, &["nothing is listening", "start the estimator first"]);

    // A file that is not a socket.
    let plain = dir.path().join("plain");
    std::fs::write(&plain, b"x").unwrap();
    let msg = external(SocketEstimator::connect(&plain, &mesh()));
    assert_mentions(&msg, &plain, &["not a socket"]);
}

#[test]
fn a_refused_hello_gives_the_reason() {
    let peer = Peer::start(&["--quiet", "--fault", "refuse"]);
    let msg = external(SocketEstimator::connect(&peer.socket, &mesh()));
    assert_mentions(&msg, &peer.socket, &["refused the connection", "refused by --fault refuse"]);
}

#[test]
fn a_peer_of_another_version_is_refused() {
    let peer = Peer::start(&["--quiet", "--fault", "bad-hello"]);
    let msg = external(SocketEstimator::connect(&peer.socket, &mesh()));
    assert_mentions(&msg, &peer.socket, &["version 99", "\"hitl-pose\" version 1"]);
}

#[test]
fn garbage_is_not_json() {
    let (msg, _peer) = frame_fault("garbage");
    assert!(msg.contains("not JSON") && msg.contains("this is not json"), "{msg}");
}

#[test]
fn a_peer_closing_before_its_reply_is_reported_and_reconnected() {
    let peer = Peer::start(&["--fault", "close", "--fault-count", "1"]);
    let mut est = connect(&peer);
    let msg = external(est.estimate(&frame(5)));
    assert_mentions(&msg, &peer.socket, &["closed the connection before replying to frame 5"]);
    // The next frame connects again.
    let f = frame(6);
    assert_centroid_pose(&est.estimate(&f).unwrap(), &f);
    assert_eq!(peer.connections(), 2, "peer log: {}", peer.log_text());
}

#[test]
fn a_truncated_reply_is_closed_mid_message() {
    let (msg, _peer) = frame_fault("truncated");
    assert!(msg.contains("in the middle of its reply") && msg.contains("10 of 100"), "{msg}");
}

#[test]
fn a_wrong_seq_is_out_of_step() {
    let (msg, _peer) = frame_fault("wrong-seq");
    assert!(msg.contains("carries seq 6") && msg.contains("out of step"), "{msg}");
}

#[test]
fn a_huge_header_length_is_refused_unallocated() {
    let (msg, _peer) = frame_fault("huge-length");
    assert!(msg.contains("4294967280-byte header") && msg.contains("1 MiB limit"), "{msg}");
}

#[test]
fn a_nan_pose_is_an_error() {
    let (msg, _peer) = frame_fault("nan");
    assert!(msg.contains("NaN") && msg.contains("must be finite"), "{msg}");
}

#[test]
fn a_short_pose_is_an_error() {
    let (msg, _peer) = frame_fault("short-pose");
    assert!(msg.contains("15 numbers, expected 16"), "{msg}");
}

#[test]
fn missing_and_extra_fields_are_errors() {
    let (msg, _peer) = frame_fault("missing-field");
    assert!(msg.contains("missing field `pose`"), "{msg}");
    let (msg, _peer) = frame_fault("extra-field");
    assert!(msg.contains("unknown field `banana`"), "{msg}");
}

#[test]
fn a_non_rigid_pose_is_lost_not_an_error() {
    let peer = Peer::start(&["--quiet", "--fault", "non-rigid"]);
    let mut est = connect(&peer);
    let e = est.estimate(&frame(5)).unwrap();
    assert_eq!(e.kind, EstimateKind::Lost);
    assert!(e.pose.is_none());
}

#[test]
fn an_error_reply_keeps_the_connection() {
    let peer = Peer::start(&["--fault", "error", "--fault-count", "1"]);
    let mut est = connect(&peer);
    let msg = external(est.estimate(&frame(5)));
    assert_mentions(
        &msg,
        &peer.socket,
        &["failed on frame 5", "simulated failure (--fault error)"],
    );
    let f = frame(6);
    assert_centroid_pose(&est.estimate(&f).unwrap(), &f);
    assert_eq!(peer.connections(), 1, "peer log: {}", peer.log_text());
}

#[test]
fn a_slow_peer_times_out_then_the_next_frame_reconnects() {
    let peer = Peer::start(&["--fault", "slow", "--delay", "2", "--fault-count", "1"]);
    let config =
        SocketConfig { frame_timeout: Duration::from_millis(300), ..SocketConfig::default() };
    let mut est = SocketEstimator::connect_with(&peer.socket, &mesh(), config).unwrap();
    let t0 = Instant::now();
    let msg = external(est.estimate(&frame(5)));
    let waited = t0.elapsed();
    assert_mentions(
        &msg,
        &peer.socket,
        &["no complete reply to frame 5 within 300ms", "(the frame timeout)"],
    );
    assert!(waited >= Duration::from_millis(300), "gave up after {waited:?}");
    assert!(waited < Duration::from_millis(1800), "gave up after {waited:?}");
    // The peer finishes its nap, fails to answer the dropped connection and accepts the new one
    // (the handshake waits for it under the hello timeout); the frame is then quick.
    let f = frame(6);
    assert_centroid_pose(&est.estimate(&f).unwrap(), &f);
    assert_eq!(peer.connections(), 2, "peer log: {}", peer.log_text());
}

#[test]
fn a_failed_reset_is_reported_by_the_next_frame() {
    let peer = Peer::start(&["--fault", "reset-close", "--fault-count", "1"]);
    let mut est = connect(&peer);
    est.estimate(&frame(1)).unwrap();
    est.reset();
    let msg = external(est.estimate(&frame(2)));
    assert_mentions(
        &msg,
        &peer.socket,
        &["closed the connection before replying to reset before frame 2"],
    );
    // Reconnected on the next frame.
    let f = frame(3);
    assert_centroid_pose(&est.estimate(&f).unwrap(), &f);
    assert_eq!(peer.connections(), 2, "peer log: {}", peer.log_text());
}
