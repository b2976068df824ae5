//! The paper's depth normalisation is exact: an estimator on the normalised frame, unscaled,
//! gives the same pose as on the original frame.
#![allow(clippy::unwrap_used)]

use hitl_hal::pose;
use hitl_perception::icp::{IcpConfig, IcpTracker};
use hitl_perception::normalize::{median_target_depth, normalize_frame, DepthNormalized};
use hitl_perception::testing::{intrinsics_hfov, look_pose, render};
use hitl_perception::{PoseEstimator, TargetModel};

#[test]
fn normalised_frame_has_median_target_depth_one_metre() {
    let k = intrinsics_hfov(160, 128, 36.5);
    let mesh = TargetModel::from_spec("two-planes").unwrap().lab_mesh(0.05).unwrap();
    let frame = render(&mesh, &look_pose(2.5, 0.3, 0.1, 0.2), &k, 0);
    let d = median_target_depth(&frame).unwrap();
    assert!((d - 2.5).abs() < 0.06, "median {d}");
    let (n, kf) = normalize_frame(&frame).unwrap();
    assert!((kf - d).abs() < 1e-12);
    let dn = median_target_depth(&n).unwrap();
    assert!((dn - 1.0).abs() < 1e-6, "normalised median {dn}");
    assert_eq!(n.mask, frame.mask);
    assert_eq!(n.intrinsics, frame.intrinsics);
}

#[test]
fn icp_on_normalised_input_gives_the_same_pose_after_unscaling() {
    let k = intrinsics_hfov(160, 128, 36.5);
    let mesh = TargetModel::from_spec("asymmetric").unwrap().lab_mesh(0.1).unwrap();
    let mut plain = IcpTracker::new(&mesh, IcpConfig::default()).unwrap();
    let mut normed = DepthNormalized::new(IcpTracker::new(&mesh, IcpConfig::default()).unwrap());
    for (i, range) in [1.3, 1.25, 1.2].into_iter().enumerate() {
        let gt = look_pose(range, 0.4 + 0.03 * i as f64, -0.2, 1.0);
        let frame = render(&mesh, &gt, &k, i as u64);
        let a = plain.estimate(&frame).unwrap().pose.unwrap();
        let b = normed.estimate(&frame).unwrap().pose.unwrap();
        let (dt, dr) = pose::difference(&a, &b);
        // Same solve up to rounding (depth is stored as f32, so ~1e-7 relative).
        assert!(dt < 1e-5 * range, "frame {i}: translation differs by {dt}");
        assert!(dr < 1e-5, "frame {i}: rotation differs by {dr} rad");
    }
}

#[test]
fn scaling_identity_is_exact_in_closed_form() {
    // A uniform scaling of the scene about the camera keeps every pixel: the pinhole projection of
    // k*p equals that of p, and t_real = k * t'.
    let kk = intrinsics_hfov(64, 48, 40.0);
    let p = nalgebra::Vector3::new(0.13, -0.07, 2.9);
    for k in [0.01, 0.37, 5.0, 250.0] {
        let q = p / k;
        let u = |v: &nalgebra::Vector3<f64>| (kk.fx * v.x / v.z + kk.cx, kk.fy * v.y / v.z + kk.cy);
        let (a, b) = (u(&p), u(&q));
        assert!((a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9);
        assert!(((q * k) - p).norm() < 1e-12);
    }
}
