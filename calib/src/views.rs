//! The views `hitl calibrate` takes of the board, and the one trajectory that visits them.
//!
//! Views sit on a cap around the board's normal (as the lab configuration places the board):
//! straight on, then rings tilted 18 and 30 deg, at 0.26-0.34 m, each turned about its optical
//! axis by up to +-30 deg, so that the flange turns about three axes (what the hand-eye solution
//! needs). Each view is solved by the planner's IK (same joint table, margins and clearances),
//! must see the whole board inside the image with a margin, and is dropped otherwise. The
//! trajectory rests at each view: a minimum-jerk move in joint space, then a dwell with a capture
//! in its middle. The caller preflights it like any trajectory.

use crate::board::Board;
use hitl_hal::{Intrinsics, Pose};
use hitl_trajectories::ik::{self, IkOptions, Scene};
use hitl_trajectories::kinematics::{Joints, DOF};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::Trajectory;
use nalgebra::{Isometry3, Point3, Rotation3, UnitQuaternion, Vector3};

/// One planned view: the camera pose (base frame, OpenCV axes) and the joints that reach it.
#[derive(Debug, Clone)]
pub struct PlannedView {
    pub camera_in_base: Pose,
    pub q: Joints,
}

/// A view that was dropped, and why.
#[derive(Debug, Clone)]
pub struct DroppedView {
    pub index: usize,
    pub reason: String,
}

/// Tuning of the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewPlan {
    /// Views asked for (the first `count` of the pattern).
    pub count: usize,
    /// Seconds at rest at each view; the capture is in its middle.
    pub dwell_s: f64,
    /// Waypoint spacing of the written trajectory, seconds.
    pub waypoint_dt_s: f64,
    /// Fraction of the lab's joint speed and acceleration limits the moves use.
    pub limit_fraction: f64,
    /// Smallest distance kept between the board and the image's edge, pixels.
    pub edge_margin_px: f64,
}

impl Default for ViewPlan {
    fn default() -> Self {
        Self {
            count: 20,
            dwell_s: 0.6,
            waypoint_dt_s: 0.04,
            limit_fraction: 0.3,
            edge_margin_px: 8.0,
        }
    }
}

/// Most views the pattern has.
pub const MAX_VIEWS: usize = 25;

/// (tilt from the normal deg, azimuth deg, roll about the optical axis deg, distance m).
fn pattern() -> Vec<(f64, f64, f64, f64)> {
    let mut v = vec![(0.0, 0.0, 0.0, 0.34)];
    for i in 0..8 {
        let az = 45.0 * i as f64;
        let roll = if i % 2 == 0 { 25.0 } else { -25.0 };
        v.push((18.0, az, roll, 0.32 + 0.02 * (i % 3) as f64));
    }
    for i in 0..8 {
        let az = 22.5 + 45.0 * i as f64;
        let roll = if i % 2 == 0 { -30.0 } else { 30.0 };
        v.push((30.0, az, roll, 0.34 + 0.02 * (i % 3) as f64));
    }
    for i in 0..8 {
        let az = 45.0 * i as f64;
        v.push((8.0, az, 45.0 * if i % 2 == 0 { 1.0 } else { -1.0 }, 0.30 + 0.02 * (i % 4) as f64));
    }
    v
}

/// The board's corners that must be in view, in the base frame, for `lab`'s nominal placement.
pub fn board_in_base(lab: &LabConfig, board: &Board) -> Pose {
    lab.target_in_base() * board.placement.board_in_target()
}

/// Where the board's corners fall in an image taken from `camera` (None: behind the camera).
pub fn board_pixels(
    board: &Board,
    board_in_base: &Pose,
    camera: &Pose,
    k: &Intrinsics,
) -> Option<Vec<(f64, f64)>> {
    let cam_board = camera.inverse() * board_in_base;
    let mut out = Vec::new();
    for t in 0..board.tag_count() {
        for p in board.corners(t) {
            let c = cam_board * p;
            if c.z <= 0.05 {
                return None;
            }
            out.push(k.project(c.x, c.y, c.z));
        }
    }
    Some(out)
}

/// Plan the views of `board` in `lab` for a camera with intrinsics `k`: those kept (in the
/// order they will be visited) and those dropped with the reason.
pub fn plan_views(
    lab: &LabConfig,
    board: &Board,
    k: &Intrinsics,
    plan: &ViewPlan,
) -> (Vec<PlannedView>, Vec<DroppedView>) {
    let z = board_in_base(lab, board);
    let (w, h) = board.extent_m();
    let centre = z * Point3::new(w / 2.0, h / 2.0, 0.0);
    let normal = -(z.rotation * Vector3::z()); // towards the viewer
    let board_x = z.rotation * Vector3::x();
    let mount = lab.camera_mount();
    let scene = Scene::from_lab(lab);
    let opts = IkOptions::for_lab(lab);
    let mut kept = Vec::new();
    let mut dropped = Vec::new();
    // Two perpendicular directions in the board plane for the azimuth.
    let e1 = board_x;
    let e2 = normal.cross(&e1);
    for (index, (tilt, az, roll, dist)) in
        pattern().into_iter().take(plan.count.min(MAX_VIEWS)).enumerate()
    {
        let (tilt, az, roll) = (tilt.to_radians(), az.to_radians(), roll.to_radians());
        let dir = normal * tilt.cos() + (e1 * az.cos() + e2 * az.sin()) * tilt.sin();
        let eye = centre + dir * dist;
        let zc = (centre - eye).normalize();
        // Image x along the board's x (as printed) before the roll.
        let xc0 = (board_x - zc * board_x.dot(&zc)).normalize();
        let yc0 = zc.cross(&xc0);
        let r = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[xc0, yc0, zc]));
        let r = r * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
        let camera =
            Isometry3::from_parts(eye.coords.into(), UnitQuaternion::from_rotation_matrix(&r));
        let in_view = board_pixels(board, &z, &camera, k).is_some_and(|px| {
            px.iter().all(|(u, v)| {
                *u >= plan.edge_margin_px
                    && *v >= plan.edge_margin_px
                    && *u <= f64::from(k.width) - 1.0 - plan.edge_margin_px
                    && *v <= f64::from(k.height) - 1.0 - plan.edge_margin_px
            })
        });
        if !in_view {
            dropped.push(DroppedView {
                index,
                reason: "the board would not be wholly in the image".into(),
            });
            continue;
        }
        // Of the clear solutions, the one nearest a forward-leaning posture (shoulder turned to
        // the view, upper arm forward, elbow bent), so that every view is on the same branch and
        // the moves between views stay small.
        let yaw = eye.y.atan2(eye.x);
        let preferred: Joints = [yaw, 0.3, 0.0, 1.2, 0.0, 0.9, 0.0];
        let sols = ik::solve_from_seeds(&camera, &mount, Some(&scene), &opts, 8);
        let best = sols.iter().min_by(|a, b| {
            let d = |q: &Joints| (0..DOF).map(|j| (q[j] - preferred[j]).powi(2)).sum::<f64>();
            d(a).total_cmp(&d(b))
        });
        match best {
            Some(q) => kept.push(PlannedView { camera_in_base: camera, q: *q }),
            None => dropped.push(DroppedView {
                index,
                reason: "no joint solution inside the limits and clear of the keep-outs".into(),
            }),
        }
    }
    (order_views(kept), dropped)
}

/// Visit order: greedy nearest neighbour in joint space from the straight-on view.
fn order_views(mut views: Vec<PlannedView>) -> Vec<PlannedView> {
    let mut out = Vec::with_capacity(views.len());
    if views.is_empty() {
        return out;
    }
    out.push(views.remove(0));
    while !views.is_empty() {
        let last = out[out.len() - 1].q;
        let (i, _) = views
            .iter()
            .enumerate()
            .map(|(i, v)| (i, (0..DOF).map(|j| (v.q[j] - last[j]).abs()).fold(0.0, f64::max)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0, 0.0));
        out.push(views.remove(i));
    }
    out
}

/// The trajectory that rests at each view in turn with a capture in the middle of each rest.
pub fn trajectory(views: &[PlannedView], lab: &LabConfig, plan: &ViewPlan) -> Trajectory {
    let mut qpos: Vec<Joints> = Vec::new();
    let mut t: Vec<f64> = Vec::new();
    let mut capture = Vec::new();
    let dt = plan.waypoint_dt_s;
    let dwell_n = ((plan.dwell_s / dt).round() as usize).max(3);
    let mut now = 0.0;
    let mut push =
        |q: Joints, cap: bool, qpos: &mut Vec<Joints>, t: &mut Vec<f64>, now: &mut f64| {
            qpos.push(q);
            t.push(*now);
            capture.push(cap);
            *now += dt;
        };
    for (i, v) in views.iter().enumerate() {
        if i > 0 {
            let a = views[i - 1].q;
            let b = v.q;
            let dur = move_duration(&a, &b, lab, plan.limit_fraction);
            let n = ((dur / dt).ceil() as usize).max(2);
            for s in 1..n {
                let x = s as f64 / n as f64;
                let m = x * x * x * (10.0 - 15.0 * x + 6.0 * x * x);
                let mut q = a;
                for j in 0..DOF {
                    q[j] = a[j] + (b[j] - a[j]) * m;
                }
                push(q, false, &mut qpos, &mut t, &mut now);
            }
        }
        for s in 0..dwell_n {
            push(v.q, s == dwell_n / 2, &mut qpos, &mut t, &mut now);
        }
    }
    Trajectory {
        qpos,
        t,
        capture: Some(capture),
        meta: Some(format!(
            "{{\"kind\": \"calibration\", \"views\": {}, \"planner\": \"hitl calibrate\"}}",
            views.len()
        )),
        ..Trajectory::default()
    }
}

/// Duration of a minimum-jerk move from `a` to `b` within `fraction` of the lab's joint speed,
/// acceleration and jerk limits (peak speed 1.875 d/T, acceleration 5.77 d/T^2, jerk 60 d/T^3).
fn move_duration(a: &Joints, b: &Joints, lab: &LabConfig, fraction: f64) -> f64 {
    let l = &lab.limits;
    let mut dur: f64 = 0.5;
    for j in 0..DOF {
        let d = (b[j] - a[j]).abs();
        dur = dur
            .max(1.875 * d / (fraction * l.velocity_rad_s[j]))
            .max((5.774 * d / (fraction * l.acceleration_rad_s2[j])).sqrt())
            .max((60.0 * d / (fraction * l.jerk_rad_s3[j])).cbrt());
    }
    dur
}
