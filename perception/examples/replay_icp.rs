//! Developer tool: re-runs the ICP tracker over a recording and prints the paper's metrics, the
//! same figures as `hitl eval RUN.mcap --backend icp --json` without building the controller
//! (tuning the tracker on recordings). `cargo run --release -p hitl-perception --example
//! replay_icp -- RUN.mcap [TARGET]`. The figures come up to the target's declared symmetry too;
//! `POLISH_POINTS=N` and `PIXEL_ITERS=N` set registration's last stage (0 points: off).

#[path = "common/icp_env.rs"]
mod icp_env;

use hitl_perception::icp::IcpTracker;
use hitl_perception::metrics::{evaluate_symmetric, PosePair};
use hitl_perception::{PoseEstimator, TargetModel};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().ok_or("usage: replay_icp RUN.mcap [TARGET]")?);
    let rec = hitl_record::reader::read_recording(&path)?;
    let run = rec.metadata.get("run").ok_or("no run metadata")?;
    let scale: f64 = run.get("scale").ok_or("no scale")?.parse()?;
    let target = args.next().or_else(|| run.get("target_model").cloned()).unwrap_or_default();
    let model = TargetModel::from_spec(&target)?;
    let mesh = model.lab_mesh(scale)?;
    let cfg = icp_env::icp_config_from_env();
    let mut tracker = IcpTracker::new(&mesh, cfg)?.with_symmetry(&model.lab_symmetry(scale));
    let gt: BTreeMap<u64, _> = rec.pose_gt.iter().map(|p| (p.capture_ns, p.pose)).collect();
    let mut est = BTreeMap::new();
    let t0 = std::time::Instant::now();
    hitl_perception::replay::replay_frames(&path, |f| {
        let e = tracker.estimate(&f).ok().and_then(|e| e.pose);
        if e.is_none() {
            tracker.reset();
        }
        est.insert(f.timestamp_ns, e);
    })?;
    let secs = t0.elapsed().as_secs_f64();
    let pairs: Vec<PosePair> = gt
        .iter()
        .map(|(t, g)| PosePair { timestamp_ns: *t, gt: *g, est: est.get(t).copied().flatten() })
        .collect();
    if std::env::var_os("PER_FRAME").is_some() {
        for p in &pairs {
            if let Some(e) = p.est {
                let d = e.inverse() * p.gt;
                println!(
                    "raw e_r {:.2} deg, e_t {:.2} mm (lab)",
                    d.rotation.angle().to_degrees(),
                    (e.translation.vector - p.gt.translation.vector).norm() * 1e3
                );
            } else {
                println!("lost");
            }
        }
    }
    let first = pairs.iter().find_map(|p| p.est.map(|e| e.rotation.angle_to(&p.gt.rotation)));
    let m = evaluate_symmetric(&pairs, scale, &model.symmetry_group)?;
    println!(
        "{} frames/s {:.2} frame0_raw_er_deg {:.3}",
        m.to_json(),
        est.len() as f64 / secs,
        first.unwrap_or(f64::NAN).to_degrees()
    );
    Ok(())
}
