//! The five detailed built-in spacecraft go through the stub's MuJoCo scene and renderer as they
//! are (5 000-60 000 faces, one mesh per material): each renders at 96x64 with its target mask
//! and depth, in several materials' colours, and loads and draws in well under a second a frame.
#![cfg(feature = "stub")]

use hitl::devices::stub::stub_target;
use hitl_perception::models::SPACECRAFT_NAMES;
use hitl_perception::TargetModel;
use hitl_sim_stub::camera::{GlRenderer, Preset};
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::time::Instant;

const W: u32 = 96;
const H: u32 = 64;

#[test]
fn each_detailed_spacecraft_renders_with_its_mask_depth_and_materials() {
    let lab = LabConfig::default();
    for name in SPACECRAFT_NAMES {
        let target = TargetModel::from_spec(name).expect("built-in");
        let size = 0.3;
        let t0 = Instant::now();
        let stub = stub_target(&target, size / target.greatest_dimension_m());
        let model = LabModel::generated(&lab, &stub).expect("lab with the target");
        let mut gl = GlRenderer::new(model, W, H).expect("MuJoCo renderer (EGL)");
        let load_s = t0.elapsed().as_secs_f64();
        gl.set_joints(&[0.0; 7]);
        let pose = lab.base_in_lab() * lab.target_in_base();
        let centre = Point3::from(pose.translation.vector);
        let eye = centre + pose.rotation * Vector3::new(0.5, 0.6, 0.6).normalize() * 0.45;
        let look = UnitQuaternion::face_towards(&(centre - eye), &Vector3::z());
        let camera = Isometry3::from_parts(Translation3::from(eye.coords), look);
        let t1 = Instant::now();
        let img = gl.render_from(&camera, &Preset::Wfov.at(W, H), 1.0, [0.0, 0.0]).expect("render");
        let frame_s = t1.elapsed().as_secs_f64();
        let on: Vec<usize> = (0..(W * H) as usize).filter(|&i| img.mask[i] == 255).collect();
        let mut colours: Vec<[u8; 3]> = on
            .iter()
            .map(|&i| [img.color[3 * i] / 32, img.color[3 * i + 1] / 32, img.color[3 * i + 2] / 32])
            .collect();
        colours.sort_unstable();
        colours.dedup();
        eprintln!(
            "{name}: {} faces, scene built in {load_s:.2} s, frame in {frame_s:.3} s, {} target \
             pixels, {} colour bins",
            target.mesh.faces().len(),
            on.len(),
            colours.len()
        );
        assert!(on.len() > 200, "{name}: {} target pixels", on.len());
        assert!(on.iter().all(|&i| img.depth_m[i] > 0.2 && img.depth_m[i] < 0.7), "{name}: depth");
        assert!(colours.len() >= 4, "{name}: {} colour bins", colours.len());
        assert!(frame_s < 2.0, "{name}: a 96x64 frame took {frame_s} s");
    }
}
