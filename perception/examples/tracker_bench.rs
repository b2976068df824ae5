//! Developer tool: the tracker bench (`hitl bench tracker`) without building the controller, for
//! tuning the tracker. `cargo run --release -p hitl-perception --example tracker_bench --
//! [ideal|orbbec] [sim|rendered] FRAMES TARGET...` at the Orbbec preset's 1280x800.
//! `POLISH_POINTS=N` and `PIXEL_ITERS=N` set registration's last stage (0 points: off, the tracker before it).

#[path = "common/icp_env.rs"]
mod icp_env;

use hitl_perception::tracker_bench::{run_with, TrackerBenchOptions};
use hitl_sim_stub::camera::{DepthModel, NoiseModel, Preset, StereoDepth};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let depth = args.first().cloned().unwrap_or_else(|| "orbbec".into());
    let mask = args.get(1).map(String::as_str) == Some("rendered");
    let frames = args.get(2).and_then(|f| f.parse().ok()).unwrap_or(60);
    let targets: Vec<String> = args.iter().skip(3).cloned().collect();
    let o = TrackerBenchOptions {
        intrinsics: Preset::Orbbec.intrinsics(),
        depth_model: depth.clone(),
        rendered_mask: mask.then_some(2),
        targets,
        range_m: 10.0,
        frames,
    };
    let mut noise = NoiseModel {
        depth_model: DepthModel::Orbbec(StereoDepth::GEMINI_305),
        seed: 23,
        ..Default::default()
    };
    match std::env::var("XDEPTH").as_deref() {
        Ok("holes") => {
            noise.depth_model =
                DepthModel::Orbbec(StereoDepth { k_per_m: 0.0, ..StereoDepth::GEMINI_305 })
        }
        Ok("noise") => {
            noise.depth_model = DepthModel::Ideal;
            noise.depth_k_per_m = 0.02;
        }
        _ => {}
    }
    let orbbec =
        move |i: u64, d: &mut [f32], k: &hitl_hal::Intrinsics| noise.draw(i).apply_depth(d, k);
    let degrade: Option<hitl_perception::tracker_bench::DepthModel<'_>> =
        (depth == "orbbec").then_some(&orbbec);
    let cfg = icp_env::icp_config_from_env();
    println!("{}", run_with(&o, degrade, &cfg));
}
