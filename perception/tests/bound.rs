//! The bound on what one frame can say of the pose (issue 23): a flat plate seen face on pins its
//! two tilts to the figure the least-squares formula gives, and its turn about the line of sight
//! not at all; the noise it is handed is the noise it measures; and the mask, grown by a margin,
//! charges nothing for a turn that moves the outline less than the margin.
#![allow(clippy::unwrap_used)]

use hitl_hal::Pose;
use hitl_perception::bound::{depth_bound, mask_room};
use hitl_perception::testing::{intrinsics_hfov, look_pose, render};
use hitl_perception::{Mesh, PerceptionFrame};
use rand::rngs::Xoshiro256PlusPlus;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// A square plate 20 mm on a side in the target's x-y plane, centred on its origin.
fn plate() -> Mesh {
    let h = 0.01;
    Mesh::new(
        vec![[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap()
}

/// Depth noise of the plate's frames, metres.
const SIGMA: f64 = 5e-4;

/// The plate face on at 0.15 m, 640x400, with `SIGMA` of depth noise on every pixel: the frame,
/// the plate and its true pose.
fn plate_frame() -> (PerceptionFrame, Mesh, Pose) {
    let mesh = plate();
    let k = intrinsics_hfov(640, 400, 60.0);
    let truth = look_pose(0.15, 0.0, 0.0, 0.0);
    let mut f = render(&mesh, &truth, &k, 1);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x5EED_1234_ABCD_0001);
    let depth: Vec<f32> = f
        .depth_m
        .iter()
        .map(|&z| {
            let noise: f64 = StandardNormal.sample(&mut rng);
            if z > 0.0 {
                (f64::from(z) + SIGMA * noise) as f32
            } else {
                0.0
            }
        })
        .collect();
    f.depth_m = depth.into();
    (f, mesh, truth)
}

#[test]
fn a_plate_face_on_pins_its_tilts_as_least_squares_does_and_its_roll_not_at_all() {
    let sigma = SIGMA;
    let (f, mesh, truth) = plate_frame();
    let b = depth_bound(&f, &mesh, &truth, |_| sigma).unwrap();
    assert!(b.counted > 4000 && b.counted == b.target_pixels, "{b:?}");
    // A tilt by t about the camera's x axis moves the plate's depth at lateral offset y by t y:
    // the information is sum(y^2) / sigma^2 (sum(y) = 0 on the centred plate), likewise about y.
    let k = f.intrinsics;
    let w = k.width as usize;
    let (mut sxx, mut syy) = (0.0, 0.0);
    for i in (0..f.depth_m.len()).filter(|&i| f.is_target(i)) {
        let (x, y) = k.unproject((i % w) as f64, (i / w) as f64);
        sxx += (x * 0.15).powi(2);
        syy += (y * 0.15).powi(2);
    }
    let about_x = sigma / syy.sqrt();
    let about_y = sigma / sxx.sqrt();
    let mut tilts: Vec<(f64, f64)> =
        b.turns[..2].iter().map(|t| (t.axis.x.abs(), t.sigma_rad)).collect();
    tilts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (y_axis, x_axis) = (tilts[0], tilts[1]);
    assert!(x_axis.0 > 0.99 && y_axis.0 < 0.01, "tilt axes {tilts:?}");
    for (got, want) in [(x_axis.1, about_x), (y_axis.1, about_y)] {
        assert!((got / want - 1.0).abs() < 0.03, "bound {got:.6} rad, least squares {want:.6}");
    }
    // About 0.05 deg each: 5000 pixels 0.5 mm apart in depth over a 20 mm plate.
    assert!(x_axis.1.to_degrees() > 0.02 && x_axis.1.to_degrees() < 0.1, "{x_axis:?}");
    let roll = b.turns[2];
    assert!(roll.axis.z.abs() > 0.99, "{roll:?}");
    assert!(roll.sigma_rad.to_degrees() > 1e3, "a face-on plate pins its roll: {roll:?}");
    // Twice the noise, twice the bound.
    let twice = depth_bound(&f, &mesh, &truth, |_| 2.0 * sigma).unwrap();
    let ratio = twice.turns[0].sigma_rad / b.turns[0].sigma_rad;
    assert!((ratio - 2.0).abs() < 1e-6, "{ratio}");
    assert!(
        b.pinned_mean_rad() < b.pinned_rms_rad() && b.pinned_mean_rad() > 0.7 * b.pinned_rms_rad()
    );
}

#[test]
fn the_noise_measured_at_the_truth_is_the_noise_the_frame_has() {
    let sigma = SIGMA;
    let (f, mesh, truth) = plate_frame();
    let right = depth_bound(&f, &mesh, &truth, |_| sigma).unwrap();
    assert!((right.chi2_per_pixel - 1.0).abs() < 0.1, "{}", right.chi2_per_pixel);
    // Told half the noise, the pixels' spread is four times the model's (and those beyond 5
    // model sigmas, 2.5 of the frame's, are not counted).
    let wrong = depth_bound(&f, &mesh, &truth, |_| sigma / 2.0).unwrap();
    assert!(wrong.chi2_per_pixel > 3.0, "{}", wrong.chi2_per_pixel);
}

#[test]
fn the_mask_charges_nothing_for_a_turn_that_moves_the_outline_less_than_its_margin() {
    let sigma = SIGMA;
    let (mut f, mesh, truth) = plate_frame();
    // As a stereo camera and the controller's mask give it: no depth within 2 pixels of the
    // outline, the mask grown by 2 pixels.
    let (w, h) = (f.intrinsics.width as usize, f.intrinsics.height as usize);
    let drawn: Vec<bool> = f.mask.as_ref().unwrap().iter().map(|&m| m != 0).collect();
    let near = |u: usize, v: usize, want: bool| {
        (u.saturating_sub(2)..=(u + 2).min(w - 1))
            .any(|a| (v.saturating_sub(2)..=(v + 2).min(h - 1)).any(|b| drawn[b * w + a] == want))
    };
    let mut depth = f.depth_m.to_vec();
    let mut mask = vec![0u8; w * h];
    for v in 0..h {
        for u in 0..w {
            if near(u, v, true) {
                mask[v * w + u] = 255;
            }
            if near(u, v, false) {
                depth[v * w + u] = 0.0;
            }
        }
    }
    f.depth_m = depth.into();
    f.mask = Some(mask.into());
    let b = depth_bound(&f, &mesh, &truth, |_| sigma).unwrap();
    let roll = b.turns[2].axis;
    // The plate's corners lie 52 pixels from its centre: 1 deg moves them 0.9 px, 8 deg 7 px.
    for turn in [0.0f64, 1.0, -1.0] {
        let charged = mask_room(&f, &mesh, &truth, &b, &roll, turn.to_radians()).unwrap();
        assert_eq!(charged, 0, "{turn} deg");
    }
    for turn in [8.0f64, -8.0] {
        let charged = mask_room(&f, &mesh, &truth, &b, &roll, turn.to_radians()).unwrap();
        assert!(charged > 20, "{turn} deg: {charged} pixels");
    }
}
