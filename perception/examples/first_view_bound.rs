//! Developer tool: how tightly one recorded frame can pin the target's pose at all, for any
//! estimator ([`hitl_perception::bound`]). `cargo run --release -p hitl-perception --example
//! first_view_bound -- RUN.mcap [FRAME] [TARGET]`: FRAME is the capture's index (default 0, the
//! frame the paper's metric calibrates every other frame on) or `all`, TARGET the model (default
//! the run's `target_model`). The depth noise is the simulated Orbbec Gemini 305's (`hitl run
//! --depth-model orbbec`: sigma = 0.02 z^2), or `SIGMA_K` x z^2.
//!
//! For one frame: the pixels counted, how well the noise model fits them at the truth, the
//! 1-sigma bound of an unbiased estimate's turn about each principal axis (camera axes, z the
//! line of sight), the expected turn about the two best pinned ones (a floor under a run's mean
//! e_r when this is its first frame), the same with turns over 10 deg ruled out, and how many
//! pixels the mask charges a turn about each axis of 0.5-20 deg. With `all`: a line per frame (its bounds, that floor, and its calibrated
//! floor against the first frame, [`hitl_perception::bound::calibrated_floor`]) and the run's
//! floor, the calibrated floors' mean (the first frame scoring 0 as in the metric). `COV=1` adds
//! a `cov` line per frame: its capture time (ns) and each turn's axis (camera axes) and 1-sigma
//! (radians), for offline filtering experiments.

use hitl_perception::bound::{calibrated_floor, depth_bound, expected_turn_within, mask_room};
use hitl_perception::TargetModel;
use hitl_sim_stub::camera::noise::StereoDepth;
use std::collections::BTreeMap;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path =
        PathBuf::from(args.next().ok_or("usage: first_view_bound RUN.mcap [FRAME|all] [TARGET]")?);
    let want: Option<u64> = match args.next().as_deref() {
        None => Some(0),
        Some("all") => None,
        Some(n) => Some(n.parse()?),
    };
    let rec = hitl_record::reader::read_recording(&path)?;
    let run = rec.metadata.get("run").ok_or("no run metadata")?;
    let scale: f64 = run.get("scale").ok_or("no scale")?.parse()?;
    let target = args.next().or_else(|| run.get("target_model").cloned()).unwrap_or_default();
    let k = match std::env::var("SIGMA_K") {
        Ok(v) => v.parse()?,
        Err(_) => StereoDepth::GEMINI_305.k_per_m,
    };
    let mesh = TargetModel::from_spec(&target)?.lab_mesh(scale)?;
    let gt: BTreeMap<u64, _> = rec.pose_gt.iter().map(|p| (p.capture_ns, p.pose)).collect();
    let mut frames = Vec::new();
    hitl_perception::replay::replay_frames(&path, |f| {
        if want.is_none_or(|w| w == f.seq) {
            frames.push(f);
        }
    })?;
    if frames.is_empty() {
        return Err("the recording has no such frame".into());
    }
    // `all`: the first frame's bound, and each frame's floor under the metric's calibrated error.
    let mut first = None;
    let mut floors = Vec::new();
    for frame in &frames {
        let Some(truth) = gt.get(&frame.timestamp_ns).copied() else {
            println!("frame {}: no ground truth", frame.seq);
            continue;
        };
        let b = match depth_bound(frame, &mesh, &truth, |z| k * z * z) {
            Ok(b) => b,
            Err(e) => {
                println!("frame {}: {e}", frame.seq);
                continue;
            }
        };
        if want.is_none() {
            let s: Vec<String> =
                b.turns.iter().map(|t| format!("{:.2}", t.sigma_rad.to_degrees())).collect();
            // The reference frame scores 0 by construction.
            let floor = match &first {
                None => 0.0,
                Some((b0, t0, _)) => calibrated_floor(b0, t0, &b, &truth),
            };
            if first.is_none() {
                first = Some((b.clone(), truth, frame.seq));
            }
            floors.push(floor);
            if std::env::var_os("COV").is_some() {
                let c: Vec<String> = b
                    .turns
                    .iter()
                    .map(|t| format!("{} {} {} {}", t.axis.x, t.axis.y, t.axis.z, t.sigma_rad))
                    .collect();
                println!("cov {} {}", frame.timestamp_ns, c.join(" "));
            }
            println!(
                "frame {:>3}: {:>5} counted, 1-sigma turns {} deg, floor {:.2} deg, \
                 calibrated floor {:.2} deg",
                frame.seq,
                b.counted,
                s.join(" "),
                b.pinned_mean_rad().to_degrees(),
                floor.to_degrees()
            );
            continue;
        }
        println!(
            "{} frame {} ({target}, range {:.3} m lab, depth sigma {:.3} mm): {} target pixels \
             with depth, {} measure the surface, {} counted, chi2/pixel at the truth {:.2}",
            path.display(),
            frame.seq,
            truth.translation.vector.z,
            k * truth.translation.vector.z.powi(2) * 1e3,
            b.target_pixels,
            b.measuring(),
            b.counted,
            b.chi2_per_pixel
        );
        for t in &b.turns {
            let charged: Vec<String> = [0.5f64, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0]
                .iter()
                .map(|deg| {
                    let plus = mask_room(frame, &mesh, &truth, &b, &t.axis, deg.to_radians());
                    let minus = mask_room(frame, &mesh, &truth, &b, &t.axis, -deg.to_radians());
                    match (plus, minus) {
                        (Ok(p), Ok(m)) => format!("{deg}: {p}/{m}"),
                        _ => format!("{deg}: ?"),
                    }
                })
                .collect();
            println!(
                "  turn about ({:+.2} {:+.2} {:+.2}): 1-sigma {:.3} deg; mask charges +-deg {}",
                t.axis.x,
                t.axis.y,
                t.axis.z,
                t.sigma_rad.to_degrees(),
                charged.join(", ")
            );
        }
        println!(
            "  about the two best pinned axes: rms {:.3} deg, expected {:.3} deg (the floor)",
            b.pinned_rms_rad().to_degrees(),
            b.pinned_mean_rad().to_degrees()
        );
        let cut = 10f64.to_radians();
        println!(
            "  the same if the mask ruled out every turn over 10 deg about them: {:.3} deg",
            expected_turn_within(&b.pinned_covariance(), cut).to_degrees()
        );
    }
    if let (None, Some((_, _, reference))) = (want, &first) {
        println!(
            "the run's floor under mean e_r (frame {} the reference, {} of {} frames bounded): \
             {:.2} deg",
            reference,
            floors.len(),
            frames.len(),
            (floors.iter().sum::<f64>() / floors.len() as f64).to_degrees()
        );
    }
    Ok(())
}
