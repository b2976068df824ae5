//! Shared helpers of hitl-record's tests: a synthetic run and the Python peer.

#![allow(dead_code)]

use hitl_hal::{Intrinsics, Pose};
use hitl_record::*;
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use std::path::Path;
use std::process::Command;

pub const W: u32 = 16;
pub const H: u32 = 8;

/// Depth value of pixel `i` in frame `k`, metres (exact in f32 and in whole millimetres).
pub fn depth_value(k: u64, i: usize) -> f32 {
    if i % 7 == 3 {
        0.0
    } else {
        0.5 + (k as f32) * 0.125 + (i as f32) * 0.001
    }
}

pub fn frame(k: u64, t_ns: u64, with_pose: bool) -> FrameRecord {
    let n = (W * H) as usize;
    let gt = Pose::translation(0.01 * k as f64, 0.0, 1.0);
    FrameRecord {
        tick: k * 10,
        capture_ns: t_ns,
        intrinsics: Intrinsics {
            width: W,
            height: H,
            fx: 20.0,
            fy: 20.0,
            cx: 8.0,
            cy: 4.0,
            distortion: Default::default(),
        },
        color: Some(Plane {
            width: W,
            height: H,
            data: (0..n * 3).map(|i| (i % 251) as u8).collect::<Vec<_>>().into(),
        }),
        depth: Some(DepthImage::Metres(Plane {
            width: W,
            height: H,
            data: (0..n).map(|i| depth_value(k, i)).collect::<Vec<_>>().into(),
        })),
        mask: Some(Plane {
            width: W,
            height: H,
            data: (0..n).map(|i| if i % 2 == 0 { 255 } else { 0 }).collect::<Vec<_>>().into(),
        }),
        gt_pose: with_pose.then_some(gt),
        tf: Some(tf_at(t_ns, k)),
        // The trigger fired 2 ms + k us before the exposure.
        trigger_ns: Some(t_ns.saturating_sub(2_000_000 + 1000 * k)),
        light_level: None,
    }
}

pub fn tf_at(t_ns: u64, k: u64) -> TfMsg {
    let a = 0.1 * k as f64;
    TfMsg {
        t_ns,
        base_flange: Pose::from_parts(
            Translation3::new(0.3 + 0.01 * k as f64, 0.0, 0.4),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a),
        ),
        flange_camera: Pose::translation(0.0, 0.0, 0.05),
        base_target: Pose::translation(0.8, 0.0, 0.4),
    }
}

pub fn meta() -> RunMetadata {
    let mut m = RunMetadata {
        config: "rate_hz = 250\n".into(),
        trajectory_sha256: "ab".repeat(32),
        trajectory_meta: r#"{"preset":"test"}"#.into(),
        lab_config: "[enclosure]\n".into(),
        scale: Some(0.01),
        sun_phase: Some(SunPhaseTrack {
            t_s: vec![0.0, 0.5, 1.0],
            sun_phase_deg: vec![10.0, 20.0, 30.0],
        }),
        ..Default::default()
    };
    m.versions.insert("hitl".into(), "0.1.0".into());
    m
}

/// Run the official Python reader on `path`; its JSON.
pub fn python_read(path: &Path, pixels: &[usize]) -> serde_json::Value {
    let py = env!("HITL_VENV_PYTHON");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/read_mcap_check.py");
    assert!(Path::new(py).exists(), "python peer {py} missing: run make setup");
    let px: Vec<String> = pixels.iter().map(|p| p.to_string()).collect();
    let out = Command::new(py)
        .arg(script)
        .arg(path)
        .arg("--depth-pixels")
        .arg(if px.is_empty() { "0".to_string() } else { px.join(",") })
        .output()
        .expect("run python peer");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "python peer failed (run make setup?): {stdout} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&stdout).unwrap_or_else(|e| panic!("peer output {stdout}: {e}"))
}

pub fn count(v: &serde_json::Value, topic: &str) -> u64 {
    v["counts"][topic].as_u64().unwrap_or(0)
}
