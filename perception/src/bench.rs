//! Benchmarks of the built-in tracker on clean rendered frames (`hitl bench accuracy` runs
//! [`bench_accuracy`]; `hitl bench tracker` runs [`crate::tracker_bench`]).
//!
//! [`bench_tracker`]: frames per second of registration and tracking at a rendering size.
//! [`bench_accuracy`]: the paper's Table-3 style figures (mean e_t, e_r per range and target) on
//! clean synthetic depth with the ground-truth mesh: a fly-around of `frames` frames seen by a
//! WFOV camera (36.5 deg) at each real range, the lab scale chosen so the camera sits at
//! `lab_range_m`. This is the rasteriser's view, not the SITL pipeline's (the lead runs that).

use crate::icp::{IcpConfig, IcpTracker};
use crate::metrics::{evaluate, PosePair};
use crate::models::BUILTIN_NAMES;
use crate::testing::{intrinsics_hfov, look_pose, render};
use crate::{EstimateKind, PoseEstimator, TargetModel};
use std::time::Instant;

/// Pose of the target at frame `i` of the fly-around (camera circling and bobbing).
fn fly_around(i: usize, range: f64) -> hitl_hal::Pose {
    let a = (i as f64) * 0.6f64.to_radians();
    look_pose(range, 0.35 + 0.2 * (0.05 * i as f64).sin(), -0.25, 0.7 + a)
}

/// Tracker speed at `width` x `height` on `frames` frames of each built-in target at 10 m real
/// range. Reports registration time (first frame) and tracking frames/s (all later frames).
pub fn bench_tracker(width: u32, height: u32, frames: usize) -> serde_json::Value {
    let k = intrinsics_hfov(width, height, 36.5);
    let (range_real, lab_range) = (10.0, 0.5);
    let scale = lab_range / range_real;
    let mut per_model = serde_json::Map::new();
    let (mut track_s, mut track_n) = (0.0, 0usize);
    for name in BUILTIN_NAMES {
        let Some(model) = TargetModel::from_spec(name).ok() else {
            continue;
        };
        let Ok(mesh) = model.lab_mesh(scale) else {
            continue;
        };
        let Ok(mut t) = IcpTracker::new(&mesh, IcpConfig::default()) else {
            continue;
        };
        let rendered: Vec<_> = (0..frames.max(2))
            .map(|i| render(&mesh, &fly_around(i, lab_range), &k, i as u64))
            .collect();
        let t0 = Instant::now();
        let _ = t.estimate(&rendered[0]);
        let reg = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let mut reregistered = 0;
        for f in &rendered[1..] {
            if let Ok(e) = t.estimate(f) {
                if e.kind != EstimateKind::Tracked {
                    reregistered += 1;
                }
            }
        }
        let tr = t1.elapsed().as_secs_f64();
        track_s += tr;
        track_n += rendered.len() - 1;
        per_model.insert(
            name.into(),
            serde_json::json!({
                "registration_s": reg,
                "tracking_fps": (rendered.len() - 1) as f64 / tr.max(1e-9),
                "not_tracked_frames": reregistered,
            }),
        );
    }
    serde_json::json!({
        "benchmark": "perception_tracker",
        "width": width,
        "height": height,
        "frames_per_model": frames,
        "threads": 1,
        "tracking_fps": track_n as f64 / f64::max(track_s, 1e-9),
        "models": per_model,
    })
}

/// Table-3 style accuracy on synthetic depth: for each real range, each built-in target's mean
/// e_t (real m) and e_r (deg) over a `frames`-frame fly-around, and their mean over targets.
pub fn bench_accuracy(
    ranges_m: &[f64],
    width: u32,
    height: u32,
    frames: usize,
    lab_range_m: f64,
) -> serde_json::Value {
    let k = intrinsics_hfov(width, height, 36.5);
    let mut rows = Vec::new();
    for &range in ranges_m {
        let scale = lab_range_m / range;
        let mut per_model = serde_json::Map::new();
        let (mut ets, mut ers) = (Vec::new(), Vec::new());
        let mut failures = 0usize;
        for name in BUILTIN_NAMES {
            let Some(model) = TargetModel::from_spec(name).ok() else {
                continue;
            };
            let Ok(mesh) = model.lab_mesh(scale) else {
                continue;
            };
            let Ok(mut t) = IcpTracker::new(&mesh, IcpConfig::default()) else {
                continue;
            };
            let pairs: Vec<PosePair> = (0..frames)
                .map(|i| {
                    let gt = fly_around(i, lab_range_m);
                    let f = render(&mesh, &gt, &k, i as u64);
                    PosePair {
                        timestamp_ns: i as u64,
                        gt,
                        est: t.estimate(&f).ok().and_then(|e| e.pose),
                    }
                })
                .collect();
            if let Ok(m) = evaluate(&pairs, scale) {
                ets.push(m.mean_et_m);
                ers.push(m.mean_er_deg);
                failures += m.failures;
                per_model.insert(name.into(), m.to_json());
            }
        }
        rows.push(serde_json::json!({
            "range_m": range,
            "scale": scale,
            "mean_et_m": crate::metrics::mean(&ets),
            "std_et_m_between_models": crate::metrics::std(&ets),
            "mean_er_deg": crate::metrics::mean(&ers),
            "std_er_deg_between_models": crate::metrics::std(&ers),
            "et_over_range_pct": 100.0 * crate::metrics::mean(&ets) / range,
            "failures": failures,
            "models": per_model,
        }));
    }
    serde_json::json!({
        "benchmark": "perception_accuracy_synthetic",
        "camera": "WFOV 36.5 deg",
        "width": width,
        "height": height,
        "frames": frames,
        "rows": rows,
    })
}
