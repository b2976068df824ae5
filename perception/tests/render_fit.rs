//! Render-and-compare fitting (issue 23): the disagreement of a drawn pose with a stereo frame
//! is least at the true pose, a part hidden behind something nearer costs nothing, the simplex
//! brings a pose a few degrees off back to the truth, and a track the frame disagrees with is
//! registered again. Frames of the tracker bench's 10 m fly-around at 320x200 through the
//! Orbbec depth model, with the controller's drawn mask.
#![allow(clippy::unwrap_used)]

#[path = "common/stereo_view.rs"]
mod stereo_view;

use hitl_hal::Pose;
use hitl_perception::icp::compare::Comparer;
use hitl_perception::icp::fit::{fit, FitSteps};
use hitl_perception::icp::score::Hidden;
use hitl_perception::icp::{IcpConfig, IcpTracker};
use hitl_perception::{EstimateKind, PoseEstimator};
use nalgebra::{UnitQuaternion, Vector3};
use stereo_view::{stereo_view as frame, stereo_view_at};

/// Depths beyond this are the wall behind the target (0.6 m), not the target.
const FAR_M: f64 = 0.3;
/// Depth tolerance of a pixel, about 2.5 sigma of the Orbbec model's error at this range (what
/// the tracker derives from the frame).
const TOL_M: f64 = 1e-3;

fn turned(p: &Pose, deg: f64) -> Pose {
    let axis = Vector3::new(0.3, -0.8, 0.5).normalize();
    let r = UnitQuaternion::from_scaled_axis(axis * deg.to_radians());
    Pose::from_parts(p.translation, r * p.rotation)
}

#[test]
fn the_true_pose_disagrees_least_with_the_frame() {
    let (f, gt, mesh) = frame("asymmetric", 40);
    let mut c = Comparer::new(&mesh).unwrap();
    c.prepare(&f, FAR_M, Hidden::Miss);
    let at_truth = c.disagreement(&f, &gt, TOL_M, FAR_M);
    let mut last = at_truth;
    for deg in [1.0, 3.0, 10.0] {
        let d = c.disagreement(&f, &turned(&gt, deg), TOL_M, FAR_M);
        assert!(d > last, "{deg} deg off: {d:.1} px, not above {last:.1}");
        last = d;
    }
    let a = c.agreement(&f, &gt, TOL_M, FAR_M);
    assert!(a > 0.9 && a <= 1.0, "agreement at the truth {a}");
}

#[test]
fn a_part_hidden_behind_something_nearer_is_no_evidence_against_the_pose() {
    let (mut f, gt, mesh) = frame("asymmetric", 40);
    let mut c = Comparer::new(&mesh).unwrap();
    c.prepare(&f, FAR_M, Hidden::Miss);
    let clear = c.disagreement(&f, &gt, TOL_M, FAR_M);
    // A bar in front of the target's lower rows: the mask loses them (as the controller's
    // drawing with the stand as occluder does), the depth sees the bar, nearer.
    let w = f.intrinsics.width as usize;
    let mask = f.mask.as_ref().unwrap().clone();
    let rows: Vec<usize> = (0..f.intrinsics.height as usize)
        .filter(|v| (0..w).any(|u| mask[v * w + u] != 0))
        .collect();
    let bar = rows[rows.len() * 3 / 4]..=rows[rows.len() - 1];
    let (mut depth, mut m) = (f.depth_m.to_vec(), mask.to_vec());
    let mut hidden = 0;
    for v in bar {
        for u in 0..w {
            let i = v * w + u;
            if m[i] != 0 {
                hidden += 1;
            }
            m[i] = 0;
            depth[i] = 0.03;
        }
    }
    f.depth_m = depth.into();
    f.mask = Some(m.into());
    c.prepare(&f, FAR_M, Hidden::Miss);
    let occluded = c.disagreement(&f, &gt, TOL_M, FAR_M);
    assert!(hidden > 20, "the bar hides {hidden} mask pixels");
    // The hidden pixels cost nothing; the rest of the target is judged as before.
    assert!(occluded <= clear + 2.0, "{occluded:.1} px with the bar, {clear:.1} without");
    // The same rows behind the target instead (background, not an occluder) cost each.
    let mut far = f.depth_m.to_vec();
    for z in far.iter_mut().filter(|z| **z == 0.03) {
        *z = 0.6;
    }
    f.depth_m = far.into();
    c.prepare(&f, FAR_M, Hidden::Miss);
    let cut = c.disagreement(&f, &gt, TOL_M, FAR_M);
    assert!(cut > occluded + 0.5 * hidden as f64, "{cut:.1} px cut off, {occluded:.1} hidden");
}

#[test]
fn the_simplex_brings_a_pose_a_few_degrees_off_back_to_the_truth() {
    for (target, view) in [("asymmetric", 40), ("one-plane", 40), ("two-planes", 20)] {
        let (f, gt, mesh) = frame(target, view);
        let mut c = Comparer::new(&mesh).unwrap();
        c.prepare(&f, FAR_M, Hidden::Miss);
        let start = turned(&gt, 3.0);
        let d = mesh.greatest_dimension();
        let steps = FitSteps { turn_rad: 2f64.to_radians(), shift_m: 0.01 * d, iters: 300 };
        let (pose, cost) = fit(&mut c, &f, &start, steps, TOL_M, FAR_M);
        let er = pose.rotation.angle_to(&gt.rotation).to_degrees();
        let before = c.disagreement(&f, &start, TOL_M, FAR_M);
        eprintln!("{target}: 3.00 -> {er:.2} deg, disagreement {before:.1} -> {cost:.1} px");
        assert!(cost < before);
        let at_truth = c.disagreement(&f, &gt, TOL_M, FAR_M);
        assert!(cost < at_truth + 1.0, "{target}: {cost:.1} px, the truth {at_truth:.1}");
        assert!(er < 1.0, "{target}: {er:.2} deg from the truth after the fit");
    }
}

/// Tracks `target` from view 40 to the same place turned `deg`, the tracker checking its tracks
/// against the frame below `min_agreement` (0: never), with `pixel_steps` pixel-wise steps on a
/// tracked frame. The second estimate's error and kind.
fn track_across_a_jump(
    target: &str,
    deg: f64,
    min_agreement: f64,
    pixel_steps: usize,
) -> (f64, EstimateKind) {
    let (f0, gt0, mesh) = frame(target, 40);
    let (f1, gt1, _) = stereo_view_at(target, 39, &turned(&gt0, deg));
    let cfg = IcpConfig {
        min_track_agreement: min_agreement,
        track_pixel_iters: pixel_steps,
        ..IcpConfig::default()
    };
    let mut tracker = IcpTracker::new(&mesh, cfg).unwrap();
    let first = tracker.estimate(&f0).unwrap().pose.unwrap();
    assert!(first.rotation.angle_to(&gt0.rotation).to_degrees() < 1.0);
    let e = tracker.estimate(&f1).unwrap();
    (e.pose.unwrap().rotation.angle_to(&gt1.rotation).to_degrees(), e.kind)
}

#[test]
fn a_track_the_frame_disagrees_with_is_registered_again() {
    // A 35 deg turn between captures (under the 45 deg a track may turn): without the tracked
    // frame's pixel-wise steps, ICP from the last pose and the fit settle 13 deg off and pass
    // the acceptance checks (measured: 13.3 deg, tracked).
    let (unchecked, kind) = track_across_a_jump("asymmetric", 35.0, 0.0, 0);
    assert!(unchecked > 5.0 && kind == EstimateKind::Tracked, "{unchecked:.2} deg, {kind:?}");
    // Its drawing disagrees with the frame: registered again, on the target (measured 0.60).
    let (checked, kind) = track_across_a_jump("asymmetric", 35.0, 0.9, 0);
    assert!(checked < 1.0 && kind == EstimateKind::Registered, "{checked:.2} deg, {kind:?}");
}

#[test]
fn a_tracked_frames_pixel_wise_steps_bring_the_track_to_what_the_frame_says() {
    // The same jump with the tracked frame's pixel-wise steps (each target pixel held against
    // the drawn surface at that pixel, as registration's last stage does) and no check: the
    // track itself comes back to the target (measured 0.73 deg; 13.3 without the steps).
    let steps = IcpConfig::default().track_pixel_iters;
    assert!(steps > 0, "the steps are on by default");
    let (tracked, kind) = track_across_a_jump("asymmetric", 35.0, 0.0, steps);
    assert!(tracked < 1.5 && kind == EstimateKind::Tracked, "{tracked:.2} deg, {kind:?}");
}

#[test]
fn the_tracker_tells_a_depth_cameras_frames_from_rendered_depth() {
    // A stereo camera's depth misses surfaces (the stand's thin legs): a tracked pose's drawing
    // where the frame has no depth is not held against it. Rendered depth misses none: there a
    // pixel without depth is empty space, as the orbit scene's sky is, and the outline counts.
    let (stereo, gt, mesh) = frame("asymmetric", 40);
    let mut t = IcpTracker::new(&mesh, IcpConfig::default()).unwrap();
    t.estimate(&stereo).unwrap();
    assert!(t.depth_misses_surfaces(), "the Orbbec model's depth taken for rendered depth");
    let rendered = hitl_perception::testing::render(&mesh, &gt, &stereo.intrinsics, 41);
    let mut t = IcpTracker::new(&mesh, IcpConfig::default()).unwrap();
    let e = t.estimate(&rendered).unwrap();
    assert_eq!(e.kind, EstimateKind::Registered);
    assert!(!t.depth_misses_surfaces(), "rendered depth taken for a camera's");
}
