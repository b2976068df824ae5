//! The paper's metrics against hand-computed cases.
#![allow(clippy::unwrap_used)]

use hitl_hal::Pose;
use hitl_perception::metrics::{evaluate, median, std, PosePair};
use nalgebra::{Quaternion, Translation3, Unit, UnitQuaternion, Vector3};

fn pose_of(axis: Vector3<f64>, angle_deg: f64, t: [f64; 3]) -> Pose {
    let r = UnitQuaternion::from_axis_angle(&Unit::new_normalize(axis), angle_deg.to_radians());
    Pose::from_parts(Translation3::new(t[0], t[1], t[2]), r)
}

fn pair(ts: u64, gt: Pose, est: Option<Pose>) -> PosePair {
    PosePair { timestamp_ns: ts, gt, est }
}

#[test]
fn a_constant_offset_is_calibrated_away() {
    // The estimator's frame differs from ground truth by a fixed body-frame offset X:
    // est = gt * X. dT = inv(est0) gt0 = inv(X), so est_k dT = gt_k exactly.
    let x = pose_of(Vector3::new(1.0, 2.0, 0.5), 37.0, [0.01, -0.02, 0.03]);
    let pairs: Vec<PosePair> = (0..5)
        .map(|k| {
            let gt =
                pose_of(Vector3::new(0.2, 1.0, 0.1), 10.0 * k as f64, [0.1 * k as f64, 0.0, 1.0]);
            pair(k, gt, Some(gt * x))
        })
        .collect();
    let m = evaluate(&pairs, 0.1).unwrap();
    assert_eq!(m.frames, 5);
    assert_eq!(m.failures, 0);
    assert!(m.mean_et_m < 1e-12, "{}", m.mean_et_m);
    assert!(m.mean_er_deg < 1e-6, "{}", m.mean_er_deg);
}

#[test]
fn hand_computed_translation_and_rotation_errors_with_scale() {
    // Frame 0 exact (dT = I). Frame 1: estimate 3 mm off in x and 4 mm in y (lab metres) and
    // rotated 2 degrees about z relative to gt. With scale 0.01 (lab m per real m):
    // e_t = 5 mm / 0.01 = 0.5 real m; e_r = 2 deg. Frame 2: 90 degrees about x, no offset.
    let gt0 = pose_of(Vector3::z(), 0.0, [0.0, 0.0, 0.5]);
    let gt1 = pose_of(Vector3::new(0.0, 1.0, 0.0), 30.0, [0.1, 0.0, 0.5]);
    let est1 = {
        let mut e = gt1 * pose_of(Vector3::z(), 2.0, [0.0, 0.0, 0.0]);
        e.translation.x += 0.003;
        e.translation.y += 0.004;
        e
    };
    let gt2 = pose_of(Vector3::z(), 0.0, [0.0, 0.1, 0.6]);
    let est2 = gt2 * pose_of(Vector3::x(), 90.0, [0.0, 0.0, 0.0]);
    let m = evaluate(
        &[pair(0, gt0, Some(gt0)), pair(1, gt1, Some(est1)), pair(2, gt2, Some(est2))],
        0.01,
    )
    .unwrap();
    let et = [0.0, 0.5, 0.0];
    let er = [0.0, 2.0, 90.0];
    for (f, (a, b)) in m.per_frame.iter().zip(et.iter().zip(er.iter())) {
        assert!((f.et_m - a).abs() < 1e-9, "e_t {} vs {a}", f.et_m);
        assert!((f.er_deg - b).abs() < 1e-9, "e_r {} vs {b}", f.er_deg);
    }
    assert!((m.mean_et_m - 0.5 / 3.0).abs() < 1e-9);
    assert!((m.median_et_m - 0.0).abs() < 1e-9);
    assert!((m.mean_er_deg - 92.0 / 3.0).abs() < 1e-9);
    assert!((m.median_er_deg - 2.0).abs() < 1e-9);
    // Population std of (0, 2, 90): mean 30.667; sqrt(((30.667)^2 + (28.667)^2 + (59.333)^2)/3).
    let expect = ((30.0f64 + 2.0 / 3.0).powi(2)
        + (28.0f64 + 2.0 / 3.0).powi(2)
        + (59.0f64 + 1.0 / 3.0).powi(2))
        / 3.0;
    assert!((m.std_er_deg - expect.sqrt()).abs() < 1e-9);
}

#[test]
fn failures_are_counted_and_the_reference_is_the_first_usable_estimate() {
    let gt = |k: u64| pose_of(Vector3::y(), k as f64, [0.0, 0.0, 1.0 + 0.01 * k as f64]);
    let off = pose_of(Vector3::x(), 5.0, [0.0, 0.01, 0.0]);
    let mut nan = gt(3) * off;
    nan.translation.x = f64::NAN;
    let pairs = vec![
        pair(0, gt(0), None),                   // no estimate
        pair(1, gt(1), Some(Pose::identity())), // identity = lost
        pair(2, gt(2), Some(gt(2) * off)),      // reference
        pair(3, gt(3), Some(nan)),              // not a pose
        pair(4, gt(4), Some(gt(4) * off)),
    ];
    let m = evaluate(&pairs, 1.0).unwrap();
    assert_eq!((m.frames, m.failures, m.scored), (5, 3, 2));
    assert_eq!(m.reference_timestamp_ns, Some(2));
    assert!(m.mean_et_m < 1e-12 && m.mean_er_deg < 1e-6);
    let j = m.to_json();
    for key in
        ["frames", "scale", "mean_et_m", "median_et_m", "mean_er_deg", "median_er_deg", "failures"]
    {
        assert!(j.get(key).is_some(), "{key} missing");
    }
}

#[test]
fn rejects_bad_scale_and_bad_ground_truth() {
    let gt = pose_of(Vector3::z(), 0.0, [0.0, 0.0, 1.0]);
    assert!(evaluate(&[pair(0, gt, Some(gt))], 0.0).is_err());
    assert!(evaluate(&[pair(0, gt, Some(gt))], f64::NAN).is_err());
    let mut bad = gt;
    bad.rotation = Unit::new_unchecked(Quaternion::new(2.0, 0.0, 0.0, 0.0)); // not a rotation
    assert!(evaluate(&[pair(0, bad, Some(gt))], 1.0).is_err());
    let m = evaluate(&[], 1.0).unwrap();
    assert_eq!(m.frames, 0);
    assert!(m.mean_et_m.is_nan());
}

#[test]
fn median_and_std_helpers() {
    assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
    assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    assert!((std(&[1.0, 3.0]) - 1.0).abs() < 1e-12);
}
