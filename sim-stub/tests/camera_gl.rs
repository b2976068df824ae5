//! MuJoCo's renderer against the ray cast and independent geometry: depth at the target's known
//! distance, the mask where the ray cast's is (straight, tilted, off-centre principal point), the
//! colour lit rather than flat, the light level obeyed, and frames through the threaded camera.
//! Small images only.

mod cube_lab;

use cube_lab::{cube_lab, HEIGHT, SIDE};
use hitl_hal::Intrinsics;
use hitl_sim_stub::camera::bench::look_at_target;
use hitl_sim_stub::camera::{
    capture_with, render_capture, FrameNoise, GlRenderer, Image, Preset, Renderer,
};
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// Both renderers on the cube lab ([`cube_lab`]).
fn cube_scene(w: u32, h: u32) -> (GlRenderer, Renderer, Isometry3<f64>, Point3<f64>) {
    let (model, camera, centre) = cube_lab();
    let mut ray = Renderer::new(model.clone()).expect("ray cast");
    ray.set_joints(&[0.0; 7]);
    let mut gl = GlRenderer::new(model, w, h).expect("MuJoCo renderer (EGL)");
    gl.set_joints(&[0.0; 7]);
    (gl, ray, camera, centre)
}

fn iou(a: &[u8], b: &[u8]) -> (f64, usize, usize) {
    let both = a.iter().zip(b).filter(|(x, y)| **x == 255 && **y == 255).count();
    let any = a.iter().zip(b).filter(|(x, y)| **x == 255 || **y == 255).count();
    let (na, nb) =
        (a.iter().filter(|x| **x == 255).count(), b.iter().filter(|x| **x == 255).count());
    (both as f64 / any.max(1) as f64, na, nb)
}

/// Median |depth difference| over pixels both renderers call target.
fn median_depth_gap(a: &Image, b: &Image) -> f64 {
    let mut d: Vec<f64> = (0..a.mask.len())
        .filter(|&i| a.mask[i] == 255 && b.mask[i] == 255)
        .map(|i| f64::from((a.depth_m[i] - b.depth_m[i]).abs()))
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(f64::INFINITY)
}

#[test]
fn depth_and_mask_match_the_ray_cast() {
    let (mut gl, mut ray, camera, _) = cube_scene(160, 128);
    let intr = Preset::Wfov.at(160, 128);
    let img = gl.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
    let want = ray.render_from(&camera, &intr, 1.0, [0.0, 0.0]);
    let (w, h) = (160usize, 128usize);
    assert_eq!((img.color.len(), img.depth_m.len(), img.mask.len()), (3 * w * h, w * h, w * h));
    // The top face is HEIGHT - SIDE/2 away along the optical axis, at every pixel on it.
    let face = HEIGHT - SIDE / 2.0;
    for (u, v) in [(80, 64), (70, 55), (90, 72)] {
        let i = v * w + u;
        assert_eq!(img.mask[i], 255, "({u},{v}) on the target");
        let z = f64::from(img.depth_m[i]);
        assert!((z - face).abs() < 0.002, "depth at ({u},{v}) {z} want {face}");
    }
    let (j, n_gl, n_ray) = iou(&img.mask, &want.mask);
    assert!(n_ray > 200, "target in view: {n_ray} px");
    // One sample per pixel centre, as the ray cast: the same pixels.
    assert!(j > 0.99, "IoU {j:.3} (MuJoCo {n_gl} px, ray cast {n_ray} px)");
    let gap = median_depth_gap(&img, &want);
    assert!(gap < 0.002, "median depth gap on the target {gap} m");
    // Only 0 and 255 in the mask; the floor around the target has depth, farther than the face.
    assert!(img.mask.iter().all(|m| *m == 0 || *m == 255));
    assert!(f64::from(img.depth_m[0]) > face, "floor depth {}", img.depth_m[0]);
}

#[test]
fn tilted_and_off_centre_cameras_see_what_the_ray_cast_sees() {
    let (mut gl, mut ray, camera, centre) = cube_scene(160, 128);
    // Turn the camera about its own x and y axes, then look back at the target from the side:
    // wrong OpenCV/MuJoCo axis handling would mirror or move the target.
    let turn = UnitQuaternion::from_euler_angles(0.25, -0.15, 0.6);
    let eye = centre + Vector3::new(0.12, -0.08, 0.22);
    let look = UnitQuaternion::face_towards(&(centre - eye), &Vector3::z());
    let tilted = Isometry3::from_parts(Translation3::from(eye.coords), look * turn.inverse());
    let tilted = tilted * UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3);
    for (name, cam, intr, shift) in [
        ("tilted", tilted, Preset::Wfov.at(160, 128), [0.0, 0.0]),
        (
            "off-centre",
            camera,
            Intrinsics {
                width: 160,
                height: 128,
                fx: 420.0,
                fy: 380.0,
                cx: 95.0,
                cy: 50.0,
                distortion: Default::default(),
            },
            [0.0, 0.0],
        ),
        ("shifted", camera, Preset::Wfov.at(160, 128), [7.0, -5.0]),
    ] {
        let img = gl.render_from(&cam, &intr, 1.0, shift).expect("render");
        let want = ray.render_from(&cam, &intr, 1.0, shift);
        let (j, n_gl, n_ray) = iou(&img.mask, &want.mask);
        assert!(n_ray > 100, "{name}: target in view ({n_ray} px)");
        assert!(j > 0.97, "{name}: IoU {j:.3} (MuJoCo {n_gl} px, ray cast {n_ray} px)");
        let gap = median_depth_gap(&img, &want);
        assert!(gap < 0.003, "{name}: median depth gap {gap} m");
    }
}

#[test]
fn colour_is_lit_and_follows_the_light_level() {
    // The cube's top face, lit by the Sun at the angle the ray cast computes: the same colour.
    let (mut gl, mut ray, camera, _) = cube_scene(160, 128);
    let intr = Preset::Wfov.at(160, 128);
    let top = gl.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
    let want = ray.render_from(&camera, &intr, 1.0, [0.0, 0.0]);
    let c = 3 * (64 * 160 + 80);
    for k in 0..3 {
        let (g, r) = (i32::from(top.color[c + k]), i32::from(want.color[c + k]));
        assert!((g - r).abs() <= 8, "top face channel {k}: MuJoCo {g}, ray cast {r}");
    }
    // The spacecraft from the arm: its faces take different light, so the colour varies.
    let lab = LabConfig::default();
    let mut gl = GlRenderer::new(LabModel::new(&lab, None).expect("lab"), 160, 128).expect("gl");
    let q = look_at_target(&lab, 0.3);
    let (lit, _) = capture_with(&mut gl, &q, &intr, 1.0, &mut FrameNoise::none()).expect("render");
    let (dark, _) = capture_with(&mut gl, &q, &intr, 0.0, &mut FrameNoise::none()).expect("render");
    let on_target: Vec<usize> = (0..lit.mask.len()).filter(|&i| lit.mask[i] == 255).collect();
    assert!(on_target.len() > 200, "target in view: {}", on_target.len());
    let lum = |img: &Image, i: usize| -> f64 {
        (0..3).map(|c| f64::from(img.color[3 * i + c])).sum::<f64>() / 3.0
    };
    let values: Vec<f64> = on_target.iter().map(|&i| lum(&lit, i)).collect();
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let (lo, hi) = values.iter().fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
    assert!(mean > 20.0, "the target is lit: mean {mean:.1}");
    assert!(hi - lo > 20.0, "shading varies across the target: {lo:.1}..{hi:.1}");
    let dark_mean = on_target.iter().map(|&i| lum(&dark, i)).sum::<f64>() / values.len() as f64;
    assert!(dark_mean < 0.5 * mean, "light off {dark_mean:.1} vs on {mean:.1}");
}

#[test]
fn a_capture_at_the_arm_joints_matches_the_ray_cast() {
    let lab = LabConfig::default();
    let model = LabModel::new(&lab, None).expect("lab");
    let mut ray = Renderer::new(model.clone()).expect("ray cast");
    let mut gl = GlRenderer::new(model, 160, 128).expect("MuJoCo renderer");
    let q = look_at_target(&lab, 0.3);
    let intr = Preset::Wfov.at(160, 128);
    let (want, want_truth) = render_capture(&mut ray, &q, &intr, 1.0, &mut FrameNoise::none());
    let (img, truth) =
        capture_with(&mut gl, &q, &intr, 1.0, &mut FrameNoise::none()).expect("render");
    assert!(
        (truth.camera_in_base.translation.vector - want_truth.camera_in_base.translation.vector)
            .norm()
            < 1e-9
    );
    let (j, n_gl, n_ray) = iou(&img.mask, &want.mask);
    assert!(n_ray > 200, "target in view: {n_ray}");
    assert!(j > 0.9, "IoU {j:.3} (MuJoCo {n_gl} px, ray cast {n_ray} px)");
    let gap = median_depth_gap(&img, &want);
    assert!(gap < 0.003, "median depth gap {gap} m");
}
