//! `hitl eval` on a recording whose numbers are known by hand: the paper's first-frame
//! calibration removes a constant estimator offset, a 2 mm lab error at scale 0.01 is 0.2 real
//! metres, a 5 degree rotation is 5 degrees, a frame without an estimate is a failure; the JSON
//! carries the keys and `--per-frame` lists every frame.

use hitl_hal::{Intrinsics, Pose};
use hitl_record::{FrameRecord, PoseStamped, Recorder, RunMetadata};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

mod common;
use common::{hitl, num};

/// Ground truth of frame k: the target 1 m ahead, drifting and turning a little each frame.
fn gt(k: usize) -> Pose {
    Isometry3::from_parts(
        Translation3::new(0.01 * k as f64, -0.02, 1.0 + 0.05 * k as f64),
        UnitQuaternion::from_euler_angles(0.1 * k as f64, 0.2, -0.05 * k as f64),
    )
}

/// Frames 0-4 at scale 0.01 (lab metres per real metre). The estimator is off by a constant
/// 30 degree turn about the target's z (the calibration removes it); frame 2 adds 2 mm along the
/// target's x, frame 3 a 5 degree turn about its x, frame 4 has no estimate.
fn write_recording(path: &Path, scale: Option<f64>) {
    let meta = RunMetadata { scale, ..Default::default() };
    let (handle, tel) = Recorder::spawn(path, &meta).expect("recorder");
    let offset = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians()),
    );
    for k in 0..5usize {
        let t = 1_000_000_000 + k as u64 * 100_000_000;
        let frame = FrameRecord {
            tick: k as u64 * 25,
            capture_ns: t,
            intrinsics: Intrinsics {
                width: 8,
                height: 8,
                fx: 10.0,
                fy: 10.0,
                cx: 4.0,
                cy: 4.0,
                distortion: Default::default(),
            },
            color: None,
            depth: None,
            mask: None,
            gt_pose: Some(gt(k)),
            tf: None,
            trigger_ns: None,
            light_level: None,
        };
        assert!(tel.push_frame(frame));
        let error = match k {
            2 => Isometry3::translation(0.002, 0.0, 0.0),
            3 => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 5f64.to_radians()),
            ),
            4 => continue,
            _ => Isometry3::identity(),
        };
        // Estimate = truth with the error in the target frame, then the estimator's offset.
        let est = gt(k) * error * offset;
        tel.push_pose_estimate(&PoseStamped { capture_ns: t, pose: est });
    }
    handle.finish().expect("recording closes");
}

#[test]
fn the_json_matches_the_hand_computed_metrics() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("run.mcap");
    write_recording(&rec, Some(0.01));
    let out = hitl(&["eval", rec.to_str().expect("utf-8"), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["frames"], 5);
    assert_eq!(v["failures"], 1);
    assert_eq!(v["scored"], 4);
    assert!((num(&v, "scale") - 0.01).abs() < 1e-15);
    // e_t per scored frame: 0, 0, 0.2, 0 real metres; e_r: 0, 0, 0, 5 degrees.
    assert!((num(&v, "mean_et_m") - 0.05).abs() < 1e-9, "{v}");
    assert!(num(&v, "median_et_m").abs() < 1e-9, "{v}");
    assert!((num(&v, "mean_er_deg") - 1.25).abs() < 1e-6, "{v}");
    assert!(num(&v, "median_er_deg").abs() < 1e-6, "{v}");
    assert!((num(&v, "std_er_deg") - (3f64.sqrt() * 5.0 / 4.0)).abs() < 1e-6, "{v}");
    assert!(v.get("per_frame").is_none(), "only with --per-frame");
}

#[test]
fn per_frame_lists_every_frame_and_marks_the_failure() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("run.mcap");
    write_recording(&rec, Some(0.01));
    let out = hitl(&["eval", rec.to_str().expect("utf-8"), "--json", "--per-frame"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let rows = v["per_frame"].as_array().expect("per_frame array");
    assert_eq!(rows.len(), 5);
    assert!((num(&rows[2], "et_m") - 0.2).abs() < 1e-9, "{}", rows[2]);
    assert!((num(&rows[3], "er_deg") - 5.0).abs() < 1e-6, "{}", rows[3]);
    assert!((num(&rows[4], "t_s") - 0.4).abs() < 1e-9);
    assert!(rows[4].get("et_m").is_none(), "frame 4 had no estimate: {}", rows[4]);

    let text = hitl(&["eval", rec.to_str().expect("utf-8"), "--per-frame"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.lines().any(|l| l.trim_start().starts_with('4') && l.ends_with("failed")),
        "{text}"
    );
    assert!(text.contains("failures 1"), "{text}");
}

#[test]
fn a_recording_without_a_scale_is_refused_unless_one_is_given() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("run.mcap");
    write_recording(&rec, None);
    let path = rec.to_str().expect("utf-8");
    let out = hitl(&["eval", path, "--json"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--scale"));
    let out = hitl(&["eval", path, "--json", "--scale", "0.02"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert!((num(&v, "mean_et_m") - 0.025).abs() < 1e-9, "{v}");
}

#[test]
fn a_file_that_is_not_a_recording_is_a_clear_error_with_exit_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("bad.mcap");
    std::fs::write(&bad, b"not an mcap file").expect("write");
    let out = hitl(&["eval", bad.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("hitl eval:") && err.contains("bad.mcap"), "{err}");
}
