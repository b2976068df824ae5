//! A view of the tracker bench's 10 m fly-around as a stereo camera delivers it, shared by the
//! tests of registration and render-and-compare fitting on a stereo camera's depth.

use hitl_hal::Pose;
use hitl_perception::silhouette::SilhouetteRenderer;
use hitl_perception::testing::render;
use hitl_perception::tracker_bench::{fly_around_pose, paper_scale};
use hitl_perception::{Mesh, PerceptionFrame, TargetModel};
use hitl_sim_stub::camera::{DepthModel, NoiseModel, Preset, StereoDepth};
use std::sync::Arc;

/// View `i` of a 41-capture fly-around of `target` at 320x200, as the bench makes it: rendered in
/// front of a wall at 0.6 m, the Orbbec depth model (z^2 error, no depth at edges and in shadows,
/// seeded), the controller's mask drawn with a 2-pixel margin. The frame, the true pose and the
/// lab mesh.
pub fn stereo_view(target: &str, i: usize) -> (PerceptionFrame, Pose, Mesh) {
    let scale = paper_scale(10.0);
    stereo_view_at(target, i, &fly_around_pose(i, 41, scale * 10.0))
}

/// [`stereo_view`] with the target at `gt` instead of the fly-around's pose `i` (`i` seeds the
/// depth noise and numbers the frame).
#[allow(dead_code)] // not every test binary that shares this file places the target itself
pub fn stereo_view_at(target: &str, i: usize, gt: &Pose) -> (PerceptionFrame, Pose, Mesh) {
    let model = TargetModel::from_spec(target).unwrap();
    let k = Preset::Orbbec.at(320, 200);
    let mesh = model.lab_mesh(paper_scale(10.0)).unwrap();
    let gt = *gt;
    let mut f = render(&mesh, &gt, &k, i as u64);
    let depth = Arc::make_mut(&mut f.depth_m);
    for z in depth.iter_mut().filter(|z| **z == 0.0) {
        *z = 0.6;
    }
    let noise = NoiseModel {
        depth_model: DepthModel::Orbbec(StereoDepth::GEMINI_305),
        seed: 23,
        ..Default::default()
    };
    noise.draw(i as u64).apply_depth(depth.as_mut_slice(), &k);
    let mut mask = Vec::new();
    SilhouetteRenderer::new(&mesh).unwrap().draw(&gt, &k, 2, &mut mask);
    f.mask = Some(mask.into());
    (f, gt, mesh)
}
