//! The ray-cast camera against independent geometry: depth at the centre pixel is the distance
//! to the target's face, the mask covers the target's projected corners, Lambert shading follows
//! the Sun, the noise options move what they say, and the threaded camera delivers frames with the
//! joints they were rendered at.

mod cube_lab;

use cube_lab::{cube, cube_lab, HEIGHT, SIDE};
use hitl_hal::{CaptureRequest, RgbdCamera, StreamConfig};
use hitl_sim_stub::camera::bench::look_at_target;
use hitl_sim_stub::camera::{
    render_capture, LightLevel, NoiseModel, Preset, Renderer, Shading, SimCamera, SimCameraConfig,
    SimCameraError,
};
use hitl_sim_stub::mujoco_plant::{LabModel, MujocoPlant};
use hitl_sim_stub::plant::Plant;
use hitl_trajectories::kinematics::camera_pose;
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, Vector3};
use std::time::{Duration, Instant};

/// A renderer of the default lab with a cube target, and a camera HEIGHT above the cube's centre
/// looking straight down (OpenCV axes: x along lab x, y along lab -y).
fn cube_scene() -> (Renderer, Isometry3<f64>, Point3<f64>) {
    let (model, camera, centre) = cube_lab();
    let mut r = Renderer::new(model).expect("renderer");
    r.set_joints(&[0.0; 7]);
    (r, camera, centre)
}

fn bbox(mask: &[u8], w: usize) -> (usize, usize, usize, usize, usize) {
    let (mut u0, mut u1, mut v0, mut v1, mut n) = (usize::MAX, 0, usize::MAX, 0, 0);
    for (i, m) in mask.iter().enumerate() {
        if *m == 255 {
            let (u, v) = (i % w, i / w);
            u0 = u0.min(u);
            u1 = u1.max(u);
            v0 = v0.min(v);
            v1 = v1.max(v);
            n += 1;
        }
    }
    (u0, u1, v0, v1, n)
}

#[test]
fn centre_depth_and_mask_match_independent_geometry() {
    let (mut r, camera, centre) = cube_scene();
    let intr = Preset::Wfov.at(320, 256);
    let img = r.render_from(&camera, &intr, 1.0, [0.0, 0.0]);
    let (w, h) = (320usize, 256usize);
    assert_eq!((img.color.len(), img.depth_m.len(), img.mask.len()), (3 * w * h, w * h, w * h));
    let c = 128 * w + 160;
    let want = HEIGHT - SIDE / 2.0;
    assert!(
        (f64::from(img.depth_m[c]) - want).abs() < 1e-6,
        "centre depth {} want {want}",
        img.depth_m[c]
    );
    assert_eq!(img.mask[c], 255);
    // Off-axis pixels on the top face have the same z-depth (not the longer ray length).
    let off = 100 * w + 120;
    assert_eq!(img.mask[off], 255);
    assert!((f64::from(img.depth_m[off]) - want).abs() < 1e-6, "z-depth {}", img.depth_m[off]);
    // Project the cube's 8 corners through the intrinsics, independently of the renderer.
    let inv = camera.inverse();
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for i in 0..8 {
        let s = |b: usize| if i >> b & 1 == 1 { SIDE / 2.0 } else { -SIDE / 2.0 };
        let p = inv * (centre + Vector3::new(s(0), s(1), s(2)));
        let (u, v) = (intr.fx * p.x / p.z + intr.cx, intr.fy * p.y / p.z + intr.cy);
        umin = umin.min(u);
        umax = umax.max(u);
        vmin = vmin.min(v);
        vmax = vmax.max(v);
    }
    let (u0, u1, v0, v1, n) = bbox(&img.mask, w);
    for (got, want) in
        [(u0, umin.ceil()), (u1, umax.floor()), (v0, vmin.ceil()), (v1, vmax.floor())]
    {
        assert!(
            (got as f64 - want).abs() <= 1.0,
            "mask box {:?} vs projection {:?}",
            (u0, u1, v0, v1),
            (umin, umax, vmin, vmax)
        );
    }
    let area = (umax - umin) * (vmax - vmin);
    assert!(
        (n as f64 - area).abs() < 2.0 * (umax - umin + vmax - vmin),
        "mask {n} px, projected {area}"
    );
    // Nothing but the target in the mask; the floor below has depth, the black background none.
    assert_eq!(img.mask.iter().filter(|m| **m != 0 && **m != 255).count(), 0);
    assert!(img.depth_m[0] > want as f32, "floor/tripod seen around the target");
}

#[test]
fn shading_follows_the_sun() {
    let (mut r, camera, _) = cube_scene();
    let intr = Preset::Wfov.at(160, 128);
    let mut brightness = |sun: Vector3<f64>, level: f32| {
        r.shading = Shading { ambient: 0.04, shadows: true, sun_direction_lab: Some(sun) };
        let img = r.render_from(&camera, &intr, level, [0.0, 0.0]);
        let c = 64 * 160 + 80;
        f64::from(img.color[3 * c])
            + f64::from(img.color[3 * c + 1])
            + f64::from(img.color[3 * c + 2])
    };
    let facing = brightness(-Vector3::z(), 1.0); // Sun on the camera's side: light travels down
    let behind = brightness(Vector3::z(), 1.0); // Sun behind the target
    let oblique = brightness(Vector3::new(0.0, 3f64.sqrt() / 2.0, -0.5), 1.0); // 60 deg off
    let dark = brightness(-Vector3::z(), 0.0);
    assert!(facing > 8.0 * behind, "facing {facing} behind {behind}");
    let want = (0.04 + 0.5) / (0.04 + 1.0);
    assert!(
        (oblique / facing - want).abs() < 0.03,
        "oblique/facing {} want {want}",
        oblique / facing
    );
    assert!((dark - behind).abs() <= 3.0, "light off {dark} vs unlit {behind}");
}

#[test]
fn pixel_noise_shifts_the_image_and_is_seeded() {
    let lab = LabConfig::default();
    let model = LabModel::generated(&lab, &cube()).expect("cube lab");
    let mut r = Renderer::new(model).expect("renderer");
    let q = look_at_target(&lab, 0.3);
    let intr = Preset::Wfov.at(320, 256);
    let clean = render_capture(&mut r, &q, &intr, 1.0, &mut NoiseModel::default().draw(5)).0;
    let noise = NoiseModel {
        sigma_px: 4.0,
        sigma_theta_deg: 0.0,
        depth_k_per_m: 0.0,
        seed: 11,
        ..NoiseModel::default()
    };
    let mut draw = noise.draw(5);
    let shift = draw.shift_px;
    let (noisy, truth) = render_capture(&mut r, &q, &intr, 1.0, &mut draw);
    assert_eq!(truth.shift_px, shift);
    let (a, b) = (bbox(&clean.mask, 320), bbox(&noisy.mask, 320));
    assert!(a.4 > 100, "target in view: {a:?}");
    let du = b.0 as f64 - a.0 as f64;
    let dv = b.2 as f64 - a.2 as f64;
    assert!(
        (du - shift[0]).abs() <= 1.5 && (dv - shift[1]).abs() <= 1.5,
        "moved ({du},{dv}) drawn {shift:?}"
    );
    let again = render_capture(&mut r, &q, &intr, 1.0, &mut noise.draw(5)).0;
    assert_eq!(again, noisy, "same seed and tick, same frame");
    // Orientation noise renders from a turned pose but keeps the nominal truth.
    let rot = NoiseModel { sigma_theta_deg: 1.0, seed: 3, ..NoiseModel::default() };
    let (_, t) = render_capture(&mut r, &q, &intr, 1.0, &mut rot.draw(9));
    let angle = t.camera_in_base.rotation.angle_to(&t.rendered_camera_in_base.rotation);
    assert!(angle > 1e-4 && angle < 0.1, "turned by {angle}");
    assert!(
        (t.camera_in_base.translation.vector
            - camera_pose(&q, &lab.camera_mount()).translation.vector)
            .norm()
            < 1e-9
    );
}

#[test]
fn threaded_camera_renders_at_the_plant_joints() {
    let lab = LabConfig::default();
    let mut plant = MujocoPlant::new(&lab, None).expect("plant");
    let q = look_at_target(&lab, 0.3);
    plant.reset(&q);
    let config = SimCameraConfig {
        intrinsics: Preset::Wfov.at(160, 128),
        queue: 1,
        ..SimCameraConfig::default()
    };
    let mut cam =
        SimCamera::new(plant.lab_model(), plant.shared_state(), LightLevel::new(0.8), config)
            .expect("camera");
    assert_eq!(cam.trigger(CaptureRequest { tick: 0, fired_ns: 0 }), Err(SimCameraError::NotArmed));
    let intr = cam
        .configure(&StreamConfig { intrinsics: Preset::Wfov.at(320, 256), mask: true })
        .expect("configure");
    cam.arm_trigger().expect("arm");
    cam.trigger(CaptureRequest { tick: 42, fired_ns: 1 }).expect("trigger");
    let deadline = Instant::now() + Duration::from_secs(20);
    let frame = loop {
        if let Some(f) = cam.poll_frame().expect("poll") {
            break f;
        }
        assert!(Instant::now() < deadline, "no frame");
        std::thread::sleep(Duration::from_millis(2));
    };
    let truth = cam.last_truth().expect("truth").clone();
    assert_eq!((frame.request.tick, truth.tick), (42, 42));
    assert_eq!(frame.intrinsics, intr);
    assert_eq!(truth.q, q);
    assert_eq!(truth.light_level, 0.8);
    // Ground truth: the target centre projected through the truth's camera pose lands on the mask.
    let cam_pose = camera_pose(&truth.q, &lab.camera_mount());
    let p = cam_pose.inverse() * lab.target_position_base();
    let (u, v) = (intr.fx * p.x / p.z + intr.cx, intr.fy * p.y / p.z + intr.cy);
    let i = v.round() as usize * 320 + u.round() as usize;
    let mask = frame.mask.as_ref().expect("mask");
    assert_eq!(mask[i], 255, "target centre at ({u:.1},{v:.1}) not in the mask");
    let depth = f64::from(frame.depth_m[i]);
    assert!(depth > 0.0 && depth < p.z && depth > p.z - 0.05, "depth {depth} vs centre {}", p.z);
    // A full queue refuses instead of blocking.
    let busy = (0..5)
        .map(|t| cam.trigger(CaptureRequest { tick: 100 + t, fired_ns: 0 }))
        .filter(|r| r.is_err())
        .count();
    assert!(busy >= 1);
}

#[test]
fn a_burst_of_captures_is_delivered_late_not_refused() {
    // Twelve triggers back to back, faster than any render: with the default exposure queue
    // every one is taken (a queue of 4 refused the fifth as busy) and every frame arrives, in
    // order, each rendered at its own exposure.
    let lab = LabConfig::default();
    let mut plant = MujocoPlant::new(&lab, None).expect("plant");
    plant.reset(&look_at_target(&lab, 0.3));
    let config = SimCameraConfig { intrinsics: Preset::Wfov.at(160, 128), ..Default::default() };
    assert!(config.queue >= 12, "exposure queue {}", config.queue);
    let mut cam =
        SimCamera::new(plant.lab_model(), plant.shared_state(), LightLevel::new(1.0), config)
            .expect("camera");
    cam.arm_trigger().expect("arm");
    for tick in 0..12u64 {
        assert_eq!(cam.trigger(CaptureRequest { tick, fired_ns: tick }), Ok(()), "capture {tick}");
    }
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut ticks = Vec::new();
    while ticks.len() < 12 {
        if let Some((frame, truth)) = cam.poll_sim_frame().expect("poll") {
            assert_eq!(frame.request.tick, truth.tick);
            ticks.push(frame.request.tick);
        }
        assert!(Instant::now() < deadline, "frames delivered: {ticks:?}");
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(ticks, (0..12).collect::<Vec<_>>());
    assert_eq!(cam.dropped_frames(), 0);
}

#[test]
fn the_exposure_is_taken_at_the_trigger_not_when_the_render_thread_gets_to_it() {
    let lab = LabConfig::default();
    let mut plant = MujocoPlant::new(&lab, None).expect("plant");
    let q1 = look_at_target(&lab, 0.3);
    plant.reset(&q1);
    let light = LightLevel::new(0.8);
    let config = SimCameraConfig {
        intrinsics: Preset::Wfov.at(160, 128),
        queue: 2,
        ..SimCameraConfig::default()
    };
    let mut cam = SimCamera::new(plant.lab_model(), plant.shared_state(), light.clone(), config)
        .expect("camera");
    cam.arm_trigger().expect("arm");
    // Two captures back to back: the render thread is still drawing the first when the arm and
    // the light change, so a camera that exposed when it got to the second would show the change.
    cam.trigger(CaptureRequest { tick: 1, fired_ns: 0 }).expect("trigger 1");
    cam.trigger(CaptureRequest { tick: 2, fired_ns: 0 }).expect("trigger 2");
    let mut q2 = q1;
    q2[0] += 0.2;
    plant.reset(&q2);
    light.set(0.1);
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut truths = Vec::new();
    while truths.len() < 2 {
        if let Some((frame, truth)) = cam.poll_sim_frame().expect("poll") {
            assert_eq!(frame.request.tick, truth.tick);
            truths.push(truth);
        }
        assert!(Instant::now() < deadline, "frames missing: {}", truths.len());
        std::thread::sleep(Duration::from_millis(1));
    }
    for t in &truths {
        assert_eq!(t.q, q1, "capture {} shows the arm after its trigger", t.tick);
        assert_eq!(t.light_level, 0.8, "capture {} lit after its trigger", t.tick);
    }
}
