use super::*;
use crate::models::TargetModel;
use crate::testing::{intrinsics_hfov, look_pose, render};

/// The first detailed spacecraft (no symmetry), 0.4 m in the lab.
fn target() -> Mesh {
    TargetModel::from_spec("sat1-none").expect("built-in").lab_mesh(0.2).expect("mesh")
}

/// A view turning 2 deg per frame about the target's y axis, 0.6 m away, 640x512.
fn views(n: usize) -> (Intrinsics, Vec<Pose>) {
    let k = intrinsics_hfov(640, 512, 60.0);
    let poses =
        (0..n).map(|i| look_pose(0.6, 0.5, 0.6 + (2.0 * i as f64).to_radians(), 0.3)).collect();
    (k, poses)
}

fn deg(a: &Pose, b: &Pose) -> f64 {
    a.rotation.angle_to(&b.rotation).to_degrees()
}

#[test]
fn tracks_from_a_known_pose_within_one_and_a_half_degrees() {
    let mesh = target();
    let (k, poses) = views(8);
    let mut t = MonoTracker::new(&mesh, MonoConfig::default()).expect("tracker");
    // Started where the first frame truly is: the keyframe is that frame's corners on the model.
    let first = render(&mesh, &poses[0], &k, 0);
    let mut lit = Vec::new();
    let (_, window) = features::lit_pixels(&first, &t.cfg, &mut lit);
    let feats = features::detect(&first, &lit, window.expect("lit"), &t.cfg, &t.pairs);
    assert!(feats.pixels.len() >= 30, "corners on the target: {}", feats.pixels.len());
    t.keyframe = Some(t.lift(&feats, &poses[0], &k));
    t.prev = Some(poses[0]);
    for (i, gt) in poses.iter().enumerate().skip(1) {
        let e = t.estimate(&render(&mesh, gt, &k, i as u64)).expect("estimate");
        assert_eq!(e.kind, EstimateKind::Tracked, "frame {i}");
        let pose = e.pose.expect("pose");
        let (er, et) = (deg(&pose, gt), (pose.translation.vector - gt.translation.vector).norm());
        assert!(er < 1.5, "frame {i}: rotation off by {er:.2} deg");
        assert!(et < 0.01, "frame {i}: translation off by {:.1} mm", et * 1e3);
    }
}

#[test]
fn registers_the_first_frame_from_its_lit_silhouette() {
    let mesh = target();
    let (k, poses) = views(3);
    let mut t = MonoTracker::new(&mesh, MonoConfig::default()).expect("tracker");
    let e = t.estimate(&render(&mesh, &poses[0], &k, 0)).expect("estimate");
    assert_eq!(e.kind, EstimateKind::Registered);
    let pose = e.pose.expect("pose");
    let er = deg(&pose, &poses[0]);
    let et = (pose.translation.vector - poses[0].translation.vector).norm();
    // A silhouette pins the pose to the grid's spacing and the search's steps: 12 deg here.
    assert!(er < 20.0, "rotation off by {er:.1} deg");
    assert!(et < 0.05, "translation off by {:.1} mm", et * 1e3);
    // The next frames track from it.
    for (i, gt) in poses.iter().enumerate().skip(1) {
        let e = t.estimate(&render(&mesh, gt, &k, i as u64)).expect("estimate");
        assert_eq!(e.kind, EstimateKind::Tracked, "frame {i}");
    }
}

#[test]
fn is_lost_in_the_dark() {
    let mesh = target();
    let (k, poses) = views(1);
    let mut frame = render(&mesh, &poses[0], &k, 0);
    // A thirty-second of the light: the flat-shaded faces (40-240) fall to 1-7, under the dark
    // level.
    for c in std::sync::Arc::make_mut(&mut frame.color).iter_mut() {
        *c /= 32;
    }
    let mut t = MonoTracker::new(&mesh, MonoConfig::default()).expect("tracker");
    let e = t.estimate(&frame).expect("estimate");
    assert_eq!(e.kind, EstimateKind::Lost);
    assert!(e.pose.is_none());
}

#[test]
fn refuses_a_frame_without_colour() {
    let mesh = target();
    let (k, poses) = views(1);
    let mut frame = render(&mesh, &poses[0], &k, 0);
    frame.color = Vec::new().into();
    let mut t = MonoTracker::new(&mesh, MonoConfig::default()).expect("tracker");
    let e = t.estimate(&frame).expect_err("no colour");
    assert!(e.to_string().contains("colour"), "{e}");
}
