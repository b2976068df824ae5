//! The stub's two scenes drawn by MuJoCo's renderer: `orbit` is black where there is no geometry
//! and `lab` is not; shadows fall (a part behind an occluder is darker than the same part lit by
//! a Sun at the same angle); moving the `orbit` Sun from one side to the other flips which half
//! of the target is brighter, whether set directly or from the run's Sun track at a capture's
//! tick; the lamp's keep-out sphere is not drawn. Small images only.
//!
//! `HITL_SCENE_DUMP=DIR` writes every image drawn here to DIR as PPM, to look at.

mod cube_lab;

use cube_lab::{box_corners, BOX_TRIANGLES};
use hitl_hal::Intrinsics;
use hitl_sim_stub::camera::{GlRenderer, Image, Preset};
use hitl_sim_stub::mjcf::{self, SceneOptions, TargetModel};
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::lab::{LabConfig, SceneKind};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

const W: u32 = 96;
const H: u32 = 64;

/// Boxes in one mesh, `[lo, hi]` corners each.
fn boxes(parts: &[([f32; 3], [f32; 3])]) -> TargetModel {
    let mut v = Vec::new();
    let mut f = Vec::new();
    for (lo, hi) in parts {
        let o = v.len() as u32;
        v.extend(box_corners(*lo, *hi));
        f.extend(BOX_TRIANGLES.map(|t| t.map(|i| o + i)));
    }
    TargetModel { mesh: Some((v, f)), greatest_dimension_m: 0.16, parts: Vec::new() }
}

/// A plate (2 x 2 x 0.1 units) with a block standing on its +x end (0.4 x 0.6 x 0.8), or its
/// -x end, scaled so the plate is 16 cm across: a block on the +x end shades the plate's middle
/// when the light comes from +x.
fn plate_and_block(block_at_plus_x: bool) -> TargetModel {
    let (x0, x1) = if block_at_plus_x { (0.6, 1.0) } else { (-1.0, -0.6) };
    boxes(&[([-1.0, -1.0, -0.1], [1.0, 1.0, 0.0]), ([x0, -0.3, 0.0], [x1, 0.3, 0.8])])
}

/// A UV sphere of unit radius, `n` segments round.
fn ball(n: u32) -> TargetModel {
    let mut v = vec![[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    let rings = n / 2;
    for r in 1..rings {
        let th = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..n {
            let ph = std::f32::consts::TAU * s as f32 / n as f32;
            v.push([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()]);
        }
    }
    let at = |r: u32, s: u32| 2 + (r - 1) * n + (s % n);
    let mut f = Vec::new();
    for s in 0..n {
        f.push([0, at(1, s), at(1, s + 1)]);
        f.push([1, at(rings - 1, s + 1), at(rings - 1, s)]);
        for r in 1..rings - 1 {
            f.push([at(r, s), at(r + 1, s), at(r + 1, s + 1)]);
            f.push([at(r, s), at(r + 1, s + 1), at(r, s + 1)]);
        }
    }
    TargetModel { mesh: Some((v, f)), greatest_dimension_m: 0.1, parts: Vec::new() }
}

fn model(kind: SceneKind, target: &TargetModel) -> LabModel {
    let lab = LabConfig::default();
    let options = SceneOptions { kind, ..SceneOptions::for_lab(&lab) };
    LabModel::generated_scene(&lab, target, &options).expect("scene")
}

/// The camera `height` above the target's centre looking straight down (OpenCV axes: x along
/// the lab's x, y along the lab's -y).
fn above_target(height: f64) -> Isometry3<f64> {
    let centre = mjcf::target_centre_lab(&LabConfig::default());
    Isometry3::from_parts(
        Translation3::from(centre.coords + Vector3::z() * height),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

fn intrinsics() -> Intrinsics {
    Preset::Orbbec.at(W, H)
}

fn dump(name: &str, img: &Image) {
    let Ok(dir) = std::env::var("HITL_SCENE_DUMP") else { return };
    let i = img.intrinsics;
    let mut out = format!("P6\n{} {}\n255\n", i.width, i.height).into_bytes();
    out.extend_from_slice(&img.color);
    let _ = std::fs::write(std::path::Path::new(&dir).join(format!("{name}.ppm")), out);
}

/// Mean grey level of the pixels `keep` accepts (pixel column, row), and how many there were.
fn mean_grey(img: &Image, keep: impl Fn(usize, usize) -> bool) -> (f64, usize) {
    let w = img.intrinsics.width as usize;
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, c) in img.color.chunks_exact(3).enumerate() {
        if keep(p % w, p / w) {
            sum += c.iter().map(|v| f64::from(*v)).sum::<f64>() / 3.0;
            n += 1;
        }
    }
    (sum / n.max(1) as f64, n)
}

/// The pixel the lab point `p` projects to from `camera` (OpenCV axes, lab frame).
fn project(camera: &Isometry3<f64>, intr: &Intrinsics, p: &Point3<f64>) -> (f64, f64) {
    let c = camera.inverse() * p;
    (intr.fx * c.x / c.z + intr.cx, intr.fy * c.y / c.z + intr.cy)
}

/// Sunlight travelling down at 45 deg, from the +x side (`from_plus_x`) or the -x side.
fn slanted_sun(from_plus_x: bool) -> Vector3<f64> {
    let x = if from_plus_x { -1.0 } else { 1.0 };
    Vector3::new(x, 0.0, -1.0).normalize()
}

#[test]
fn orbit_is_black_where_nothing_is_and_lab_is_not() {
    let target = ball(24);
    let camera = above_target(0.3);
    let intr = intrinsics();
    let mut orbit = GlRenderer::new(model(SceneKind::Orbit, &target), W, H).expect("renderer");
    orbit.set_joints(&[0.0; 7]);
    let img = orbit.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
    dump("orbit-ball", &img);
    let background: Vec<usize> = (0..img.mask.len()).filter(|&i| img.mask[i] == 0).collect();
    assert!(background.len() > img.mask.len() / 2, "the target fills the frame");
    // No floor, tripod, curtain or arm: nothing but the target, black around it, no depth.
    for &i in &background {
        assert_eq!(&img.color[3 * i..3 * i + 3], &[0, 0, 0], "pixel {i} not black");
        assert_eq!(img.depth_m[i], 0.0, "pixel {i} has depth");
    }
    let (lit, n) = mean_grey(&img, |u, v| img.mask[v * W as usize + u] == 255);
    assert!(n > 100 && lit > 20.0, "target {n} px, mean {lit:.1}");

    let mut lab = GlRenderer::new(model(SceneKind::Lab, &target), W, H).expect("renderer");
    lab.set_joints(&[0.0; 7]);
    let img = lab.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
    dump("lab-ball", &img);
    // The curtained floor is under the target: every pixel has depth, and the floor is lit.
    assert!(img.depth_m.iter().all(|z| *z > 0.0), "a pixel with no return in the lab");
    let (floor, n) = mean_grey(&img, |u, v| img.mask[v * W as usize + u] == 0);
    assert!(n > 1000 && floor > 1.0, "floor {n} px, mean {floor:.2}");
}

/// A Sun from +x puts the plate's middle in the block's shadow; the mirrored Sun (same angle on
/// the plate) lights it. The plate's far end, lit by both, is as bright under either.
#[test]
fn a_part_behind_an_occluder_is_darker_than_the_same_part_lit() {
    let camera = above_target(0.2);
    let intr = intrinsics();
    let mut r = GlRenderer::new(model(SceneKind::Orbit, &plate_and_block(true)), W, H).expect("gl");
    r.set_joints(&[0.0; 7]);
    let region = |x0: f64, x1: f64| plate_region(&camera, &intr, x0, x1);
    let mut draw = |from_plus_x: bool| {
        r.set_sun_direction(Some(slanted_sun(from_plus_x)));
        let img = r.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
        dump(&format!("shadow-from-{}", if from_plus_x { "plus-x" } else { "minus-x" }), &img);
        let (middle, n) = mean_grey(&img, region(0.05, 0.5));
        let (end, m) = mean_grey(&img, region(-0.9, -0.45));
        assert!(n >= 12 && m >= 12, "regions of {n} and {m} px");
        (middle, end)
    };
    let (shaded, end_a) = draw(true);
    let (lit, end_b) = draw(false);
    assert!(lit > 40.0, "the lit plate is dark: {lit:.1}");
    assert!(shaded < 0.4 * lit, "in the block's shadow {shaded:.1}, lit {lit:.1}");
    assert!((end_a - end_b).abs() < 0.15 * end_b, "the far end {end_a:.1} vs {end_b:.1}");
    assert!((end_a - lit).abs() < 0.15 * lit, "the far end {end_a:.1} vs the lit middle {lit:.1}");
}

/// The pixels (from `camera`, straight down) of the plate's top between x0 and x1 units and
/// within 0.2 units of its middle line. The mesh is centred on its box (z from -0.1 to 0.8
/// units), 0.08 m per unit.
fn plate_region(
    camera: &Isometry3<f64>,
    intr: &Intrinsics,
    x0: f64,
    x1: f64,
) -> impl Fn(usize, usize) -> bool {
    let centre = mjcf::target_centre_lab(&LabConfig::default());
    let on_plate = |x: f64, y: f64| centre + Vector3::new(x, y, -0.35) * 0.08;
    let (a, b) =
        (project(camera, intr, &on_plate(x0, -0.2)), project(camera, intr, &on_plate(x1, 0.2)));
    let (u0, u1) = (a.0.min(b.0), a.0.max(b.0));
    let (v0, v1) = (a.1.min(b.1), a.1.max(b.1));
    move |u: usize, v: usize| {
        let (u, v) = (u as f64, v as f64);
        u >= u0 && u <= u1 && v >= v0 && v <= v1
    }
}

/// The studio light (a spot, at +x of the target and above it) casts shadows too: the plate's
/// middle behind a block on its +x end is darker than the same middle with the block moved to
/// the -x end, out of the way.
#[test]
fn the_studio_light_casts_shadows_in_the_lab() {
    let camera = above_target(0.2);
    let intr = intrinsics();
    let mut middle = Vec::new();
    for block_at_plus_x in [true, false] {
        let m = model(SceneKind::Lab, &plate_and_block(block_at_plus_x));
        let mut r = GlRenderer::new(m, W, H).expect("gl");
        // The arm swung round behind its base, out of the light and the view.
        r.set_joints(&[2.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let img = r.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
        dump(&format!("lab-shadow-{block_at_plus_x}"), &img);
        let (grey, n) = mean_grey(&img, plate_region(&camera, &intr, 0.05, 0.5));
        assert!(n >= 12, "{n} px");
        middle.push(grey);
    }
    let (shaded, lit) = (middle[0], middle[1]);
    assert!(lit > 40.0, "the lit plate is dark: {lit:.1}");
    assert!(shaded < 0.4 * lit, "in the block's shadow {shaded:.1}, lit {lit:.1}");
}

/// Mean grey of the target's left and right halves in the image (the image's x is the lab's x).
fn halves(img: &Image) -> (f64, f64) {
    let w = img.intrinsics.width as usize;
    let (mut lo, mut hi) = (usize::MAX, 0);
    for (i, m) in img.mask.iter().enumerate() {
        if *m == 255 {
            lo = lo.min(i % w);
            hi = hi.max(i % w);
        }
    }
    assert!(lo < hi, "no target in view");
    let mid = (lo + hi) / 2;
    let on = |u: usize, v: usize| img.mask[v * w + u] == 255;
    (mean_grey(img, |u, v| on(u, v) && u < mid).0, mean_grey(img, |u, v| on(u, v) && u > mid).0)
}

#[test]
fn moving_the_orbit_sun_across_flips_the_brighter_half() {
    let camera = above_target(0.25);
    let intr = intrinsics();
    let mut r = GlRenderer::new(model(SceneKind::Orbit, &ball(24)), W, H).expect("gl");
    r.set_joints(&[0.0; 7]);
    for from_plus_x in [true, false] {
        r.set_sun_direction(Some(slanted_sun(from_plus_x)));
        let img = r.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
        dump(&format!("ball-sun-{from_plus_x}"), &img);
        let (left, right) = halves(&img);
        let (bright, dim) = if from_plus_x { (right, left) } else { (left, right) };
        assert!(bright > 1.5 * dim + 5.0, "Sun from +x {from_plus_x}: {left:.1} | {right:.1}");
        let used = r.sun_direction().expect("orbit Sun");
        assert!((used - slanted_sun(from_plus_x)).norm() < 1e-12, "{used:?}");
    }
}

/// The run's Sun track drives the `orbit` Sun at each capture's tick (the camera thread sets the
/// tick), from the loop tick where playback starts; the lab's studio light ignores it.
#[test]
fn the_sun_track_points_the_orbit_sun_at_each_capture() {
    let camera = above_target(0.25);
    let intr = intrinsics();
    let m = model(SceneKind::Orbit, &ball(24));
    let track = m.sun_track.clone();
    assert!(track.set_schedule(&[(0, slanted_sun(true)), (100, slanted_sun(false))]));
    assert!(!track.set_schedule(&[]), "set once");
    let mut r = GlRenderer::new(m, W, H).expect("gl");
    r.set_joints(&[0.0; 7]);
    track.set_playback_start(40);
    // Loop tick 40 is playback tick 0 (Sun from +x), 140 and later is tick 100 (from -x);
    // halfway the direction is the normalised mean (straight down).
    assert!((track.direction_at(90).expect("dir") - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-9);
    for (tick, from_plus_x) in [(40, true), (500, false)] {
        r.set_capture_tick(tick);
        let img = r.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
        let (left, right) = halves(&img);
        assert!((right > left) == from_plus_x, "tick {tick}: {left:.1} | {right:.1}");
        let used = r.sun_direction().expect("orbit Sun");
        assert!((used - slanted_sun(from_plus_x)).norm() < 1e-9, "tick {tick}: {used:?}");
    }
    // The lab's Sun is the studio light where it stands: a track changes nothing.
    let lab_model = model(SceneKind::Lab, &ball(24));
    lab_model.sun_track.set_schedule(&[(0, slanted_sun(false))]);
    lab_model.sun_track.set_playback_start(0);
    let mut lab = GlRenderer::new(lab_model, W, H).expect("gl");
    lab.set_joints(&[0.0; 7]);
    lab.set_capture_tick(5);
    let img = lab.render_from(&camera, &intr, 1.0, [0.0, 0.0]).expect("render");
    assert_eq!(lab.sun_direction(), None);
    // The studio light stands at +x of the target (lab (2.2, 0.3, 0.9), target x 1.35).
    let (left, right) = halves(&img);
    assert!(right > left, "lab light from +x: {left:.1} | {right:.1}");
}

/// In `lab` the light's keep-out sphere (0.2 m) collides but is not drawn: looking at the lamp
/// from 0.5 m, only its small housing is in view. In `orbit` the Earth lies along the nadir
/// (the planner's default Hill frame: up in the lab), blue, beyond the depth range.
#[test]
fn the_lamp_is_small_and_the_earth_is_up() {
    let lab = LabConfig::default();
    let lamp = Point3::from(Vector3::from(lab.light.position_lab_m));
    let centre = mjcf::target_centre_lab(&lab);
    let towards = |eye: Point3<f64>, at: Point3<f64>| {
        // OpenCV axes: z forward, y down; face_towards keeps y up, so turn half about z.
        let look = UnitQuaternion::face_towards(&(at - eye), &Vector3::z());
        Isometry3::from_parts(
            Translation3::from(eye.coords),
            look * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
        )
    };
    let intr = intrinsics();
    let m = model(SceneKind::Lab, &ball(24));
    let mut r = GlRenderer::new(m, W, H).expect("gl");
    r.set_joints(&[0.0; 7]);
    let eye = lamp + (centre - lamp).normalize() * 0.5;
    let img = r.render_from(&towards(eye, lamp), &intr, 1.0, [0.0, 0.0]).expect("render");
    dump("lamp", &img);
    // Pixels whose surface lies within the keep-out sphere's radius of the light: the housing
    // (6 cm radius) covers about 2 % of this view; a drawn sphere would cover a quarter.
    let view = towards(eye, lamp);
    let w = W as usize;
    let near = (0..img.depth_m.len())
        .filter(|&i| {
            let z = f64::from(img.depth_m[i]);
            let (u, v) = ((i % w) as f64, (i / w) as f64);
            let p = view * Point3::new((u - intr.cx) / intr.fx * z, (v - intr.cy) / intr.fy * z, z);
            z > 0.0 && (p - lamp).norm() < lab.light.keepout_radius_m
        })
        .count();
    let share = near as f64 / img.depth_m.len() as f64;
    assert!(near > 0 && share < 0.06, "the lamp covers {:.1} % of the frame", 100.0 * share);

    let mut r = GlRenderer::new(model(SceneKind::Orbit, &ball(24)), W, H).expect("gl");
    r.set_joints(&[0.0; 7]);
    let eye = centre + Vector3::new(0.0, 0.0, 0.1);
    let up = Isometry3::from_parts(Translation3::from(eye.coords), UnitQuaternion::identity());
    r.set_sun_direction(Some(Vector3::new(0.3, 0.2, 1.0)));
    let img = r.render_from(&up, &intr, 1.0, [0.0, 0.0]).expect("render");
    dump("earth", &img);
    let c = ((H / 2) * W + W / 2) as usize;
    let rgb = &img.color[3 * c..3 * c + 3];
    assert!(rgb[2] > 40 && rgb[2] > rgb[0], "the Earth's centre is not blue: {rgb:?}");
    assert_eq!(img.depth_m[c], 0.0, "the Earth is beyond the depth range");
    assert_eq!(img.mask[c], 0);
}
