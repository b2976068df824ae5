//! The NPZ benchmark: write a long trajectory, time loading it (stored and deflated) and
//! time-parametrising it at 250 Hz. `scripts/bench_npz.py` times numpy's `np.load` of the same
//! files for a side-by-side comparison.

use crate::npz;
use crate::timing::{SetpointTable, DEFAULT_RATE_HZ};
use crate::trajectory::Trajectory;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Repetitions per timing; the median is reported.
const REPEATS: usize = 5;

/// Where [`bench_npz`] leaves its files, for `scripts/bench_npz.py`.
pub fn bench_dir() -> PathBuf {
    std::env::temp_dir().join("hitl-bench-npz")
}

/// A deterministic planner-like trajectory: `n` waypoints 10 ms apart, every channel filled.
pub fn synthetic(n: usize) -> Trajectory {
    let n = n.max(2);
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
    let span = t[n - 1];
    let base = [0.0, -0.4, 0.0, 1.4, 0.0, 1.5, 0.0];
    let qpos = t
        .iter()
        .map(|x| {
            let mut q = base;
            for (j, v) in q.iter_mut().enumerate() {
                let w = 2.0 * std::f64::consts::PI * (1.0 + j as f64) / span;
                *v += 0.1 * (w * x).sin().powi(2);
            }
            q
        })
        .collect();
    Trajectory {
        qpos,
        capture: Some((0..n).map(|i| i % 25 == 0).collect()),
        light: Some((0..n).map(|i| (i % 100) as f32 / 100.0).collect()),
        u_rad: Some(t.iter().map(|x| x / span * std::f64::consts::TAU).collect()),
        rel_pos_rtn_m: Some(t.iter().map(|x| [x.cos(), x.sin(), 0.1 * x]).collect()),
        cam_pose_base: Some(
            t.iter()
                .map(|x| {
                    let (s, c) = x.sin_cos();
                    [
                        [c, -s, 0.0, 0.3],
                        [s, c, 0.0, 0.0],
                        [0.0, 0.0, 1.0, 0.4],
                        [0.0, 0.0, 0.0, 1.0],
                    ]
                })
                .collect(),
        ),
        sun_phase_deg: Some(t.iter().map(|x| (x * 3.6) % 360.0).collect()),
        meta: Some(r#"{"preset": "bench", "scale": 1.0}"#.into()),
        t,
    }
}

fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..REPEATS)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[REPEATS / 2]
}

/// Write a `waypoints`-long NPZ (stored and deflated) under [`bench_dir`], time `npz::load` of
/// each and `SetpointTable::build` at 250 Hz. Figures in milliseconds (median of 5).
pub fn bench_npz(waypoints: usize) -> Value {
    match run(waypoints, &bench_dir()) {
        Ok(v) => v,
        Err(e) => json!({ "error": e }),
    }
}

fn run(waypoints: usize, dir: &Path) -> Result<Value, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let traj = synthetic(waypoints);
    let mut files = serde_json::Map::new();
    for (name, compressed) in [("stored", false), ("deflated", true)] {
        let path = dir.join(format!("traj-{waypoints}-{name}.npz"));
        let save_ms = median_ms(|| {
            let _ = npz::save(&path, &traj, compressed);
        });
        let bytes = std::fs::metadata(&path).map_err(|e| e.to_string())?.len();
        let mut err = None;
        let load_ms = median_ms(|| {
            if let Err(e) = npz::load(&path) {
                err = Some(e.to_string());
            }
        });
        if let Some(e) = err {
            return Err(e);
        }
        files.insert(
            name.into(),
            json!({
                "path": path.display().to_string(),
                "bytes": bytes,
                "save_ms": save_ms,
                "load_ms": load_ms,
                "load_mb_per_s": bytes as f64 / 1e6 / (load_ms / 1e3),
            }),
        );
    }
    let mut ticks = 0;
    let mut err = None;
    let parametrise_ms = median_ms(|| match SetpointTable::build(&traj, DEFAULT_RATE_HZ, 1.0) {
        Ok(t) => ticks = t.ticks(),
        Err(e) => err = Some(e.to_string()),
    });
    if let Some(e) = err {
        return Err(e);
    }
    Ok(json!({
        "waypoints": traj.len(),
        "duration_s": traj.duration(),
        "files": files,
        "parametrise_ms": parametrise_ms,
        "parametrise_rate_hz": DEFAULT_RATE_HZ,
        "ticks": ticks,
        "ns_per_tick": parametrise_ms * 1e6 / ticks.max(1) as f64,
        "repeats": REPEATS,
        "statistic": "median",
        "numpy_side_by_side": "scripts/bench_npz.py (times np.load of the same files)",
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_every_figure_for_a_small_file() {
        let dir = std::env::temp_dir().join(format!("hitl-bench-test-{}", std::process::id()));
        let v = run(50, &dir).expect("bench");
        assert_eq!(v["waypoints"], 50);
        assert_eq!(v["ticks"], 124); // 0.49 s at 250 Hz: 122.5 steps rounded up to 123, plus tick 0
        for f in ["stored", "deflated"] {
            assert!(v["files"][f]["load_ms"].as_f64().is_some_and(|x| x > 0.0), "{v}");
        }
        assert!(v["files"]["deflated"]["bytes"].as_u64() < v["files"]["stored"]["bytes"].as_u64());
        let _ = std::fs::remove_dir_all(dir);
    }

    /// The real benchmark, run by hand (release build), not in CI:
    /// `cargo test -p hitl-trajectories --release --lib bench::tests::figures -- --ignored --nocapture`
    #[test]
    #[ignore = "benchmark: run by hand in release"]
    fn figures() {
        println!("{}", bench_npz(100_000));
    }
}
