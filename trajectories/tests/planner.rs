//! The orbital planner against the paper's equations and the arm's kinematics.

use hitl_trajectories::ik::{self, IkOptions, Scene};
use hitl_trajectories::kinematics::camera_pose;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::orbit::{sun_phase_deg, ChiefOrbit, Preset, Roe};
use hitl_trajectories::planner::{self, PlanError, PlanRequest, Timing};
use nalgebra::{Isometry3, Matrix4, Point3, Vector3};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn eq3_matches_hand_computed_values() {
    // delta alpha = (1, 2, 3, 4, 5, 6) * 1e-6, a = 1e7 m, u = 30 deg, u0 = 0:
    // x = 10 - 30 cos u - 40 sin u                      = -35.980762
    // y = 20 - 15 u + 60 sin u - 80 cos u               = -27.136015
    // z = 50 sin u - 60 cos u                           = -26.961524
    let roe = Roe([1e-6, 2e-6, 3e-6, 4e-6, 5e-6, 6e-6]);
    let p = roe.position_rtn(1e7, PI / 6.0, 0.0);
    assert!(close(p.x, -35.980762, 1e-5), "{p}");
    assert!(close(p.y, -27.136015, 1e-5), "{p}");
    assert!(close(p.z, -26.961524, 1e-5), "{p}");
    // The paper's fly-around at 50 m: (-50, 0, -50) at u = 0, (0, 100, 0) at u = 90 deg.
    let a = ChiefOrbit::default().a_m;
    let fly = Preset::Flyaround.roe(50.0, a);
    let p0 = fly.position_rtn(a, 0.0, 0.0);
    assert!((p0 - Vector3::new(-50.0, 0.0, -50.0)).norm() < 1e-9, "{p0}");
    let p1 = fly.position_rtn(a, FRAC_PI_2, 0.0);
    assert!((p1 - Vector3::new(0.0, 100.0, 0.0)).norm() < 1e-9, "{p1}");
    // Station keeping sits still at 50 m along-track.
    let sk = Preset::StationKeeping.roe(50.0, a);
    for u in [0.0, 1.0, 4.0] {
        assert!((sk.position_rtn(a, u, 0.0) - Vector3::new(0.0, 50.0, 0.0)).norm() < 1e-9);
    }
}

#[test]
fn closed_form_satisfies_the_hcw_equations() {
    let chief = ChiefOrbit::default();
    let (a, n) = (chief.a_m, chief.mean_motion());
    let u0 = 0.3;
    // Every element non-zero, delta a included (along-track drift).
    let roe = Roe([2e-6, -1e-6, 3e-6, -2e-6, 1.5e-6, 2.5e-6]);
    let p = |t: f64| roe.position_rtn(a, u0 + n * t, u0);
    let h = 20.0;
    let size = 100.0; // metres, the order of the motion
    for t in [0.0, 1000.0, 7777.0, 20_000.0] {
        let v = (p(t + h) - p(t - h)) / (2.0 * h);
        let acc = (p(t + h) - 2.0 * p(t) + p(t - h)) / (h * h);
        let x = p(t);
        let rx = acc.x - (3.0 * n * n * x.x + 2.0 * n * v.y);
        let ry = acc.y + 2.0 * n * v.x;
        let rz = acc.z + n * n * x.z;
        let scale = n * n * size;
        for r in [rx, ry, rz] {
            assert!(r.abs() < 1e-5 * scale, "residual {r:e} vs {scale:e} at t = {t}");
        }
        // The analytic du-derivative agrees with the finite difference.
        let vd = roe.position_rtn_du(a, u0 + n * t) * n;
        assert!((vd - v).norm() < 1e-4 * n * size, "{vd} vs {v}");
    }
}

#[test]
fn sun_phase_is_oriented_as_the_paper_says() {
    let chief = ChiefOrbit::default();
    let u = 0.4;
    let m = chief.rtn_to_eci(u);
    let sun_eci = m * Vector3::new(1.0, 0.0, 0.0); // the Sun along R at this u
    let ph = |rel: Vector3<f64>| sun_phase_deg(&chief, u, &rel, &sun_eci).expect("phase");
    assert!(close(ph(Vector3::new(5.0, 0.0, 0.0)), 0.0, 1e-9)); // chaser between Sun and target
    assert!(close(ph(Vector3::new(-5.0, 0.0, 0.0)), 180.0, 1e-9)); // target between
                                                                   // (sun x chaser) . N > 0: chaser at +T is ahead about N: approaching (0-180).
    assert!(close(ph(Vector3::new(0.0, 5.0, 0.0)), 90.0, 1e-9));
    assert!(close(ph(Vector3::new(0.0, -5.0, 0.0)), 270.0, 1e-9));
    // A chaser at rest in RTN sweeps the phase upward over the orbit (the Sun turns about -N).
    let rel = Vector3::new(0.0, 50.0, 0.0);
    let sun = Vector3::new(1.0, 0.0, 0.0);
    let mut last = sun_phase_deg(&chief, 0.0, &rel, &sun).expect("phase");
    let mut wraps = 0;
    for k in 1..=360 {
        let p = sun_phase_deg(&chief, TAU * k as f64 / 360.0, &rel, &sun).expect("phase");
        if p < last - 180.0 {
            wraps += 1;
        } else {
            assert!(p >= last - 1e-9, "phase went back from {last} to {p}");
        }
        last = p;
    }
    assert!(wraps <= 1);
}

fn short_flyaround() -> PlanRequest {
    PlanRequest {
        timing: Timing::DurationS(40.0),
        waypoints: Some(601),
        revolutions: 2,
        capture_every: 4,
        ramp_s: 1.5,
        ..PlanRequest::default()
    }
}

/// The two-revolution plan several tests look at, planned once.
fn shared_plan() -> &'static planner::Plan {
    static PLAN: std::sync::OnceLock<planner::Plan> = std::sync::OnceLock::new();
    PLAN.get_or_init(|| {
        planner::plan(&short_flyaround(), &LabConfig::default(), &mut |_, _| {}).expect("plan")
    })
}

fn pose_from_rows(r: &[[f64; 4]; 4]) -> Isometry3<f64> {
    let m = Matrix4::from_fn(|i, j| r[i][j]);
    let rot = nalgebra::Rotation3::from_matrix_unchecked(m.fixed_view::<3, 3>(0, 0).into_owned());
    Isometry3::from_parts(
        nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        nalgebra::UnitQuaternion::from_rotation_matrix(&rot),
    )
}

#[test]
fn planned_joints_reproduce_the_camera_poses_and_look_at_the_target() {
    let lab = LabConfig::default();
    let plan = shared_plan();
    let traj = &plan.trajectory;
    assert_eq!(traj.len(), 601);
    let mount = lab.camera_mount();
    let target = lab.target_position_base();
    let cams = traj.cam_pose_base.as_ref().expect("cam_pose_base");
    for (k, (q, rows)) in traj.qpos.iter().zip(cams).enumerate() {
        let want = pose_from_rows(rows);
        let got = camera_pose(q, &mount);
        let dp = (got.translation.vector - want.translation.vector).norm();
        let dr = (got.rotation.inverse() * want.rotation).angle().to_degrees();
        assert!(dp < 1e-4, "waypoint {k}: {dp} m");
        assert!(dr < 0.01, "waypoint {k}: {dr} deg");
        // The optical axis (camera z) passes through the target centre.
        let z = got.rotation * Vector3::z();
        let to_target = target - Point3::from(got.translation.vector);
        let miss = (to_target - z * to_target.dot(&z)).norm();
        assert!(miss < 1e-6 && to_target.dot(&z) > 0.0, "waypoint {k}: misses by {miss} m");
        // Joint limits of the lab's table, with the lab's margin.
        let limits = lab.arm.joint_table.limits();
        assert_eq!(
            hitl_trajectories::kinematics::first_joint_beyond_limits(q, &limits, 0.05),
            None
        );
    }
    // Captures every 4th waypoint; light constant; Sun phase in range.
    assert_eq!(traj.capture_count(), 151);
    assert!(traj.light.as_ref().expect("light").iter().all(|l| *l == 1.0));
    assert!(traj.sun_phase_deg.as_ref().expect("sun").iter().all(|p| (0.0..360.0).contains(p)));
    // The camera-target range follows the scaled 2:1 ellipse: r sqrt(2) .. 2r times the scale.
    let s = plan.summary.scale;
    assert!(close(s, 0.11 * 0.7 / 50.0, 1e-15));
    assert!(plan.summary.min_camera_target_m >= 50.0 * 2f64.sqrt() * s - 1e-9);
    assert!(plan.summary.max_camera_target_m <= 100.0 * s + 1e-9);
}

#[test]
fn windup_alternates_direction_and_rests_at_the_ends() {
    let plan = shared_plan();
    let u = plan.trajectory.u_rad.as_ref().expect("u_rad");
    let u0 = ChiefOrbit::default().u0_rad();
    let n = u.len();
    let mid = n / 2; // 601 waypoints over 2 passes of equal length: waypoint 300 is the turn.
    assert!(close(u[0], u0, 1e-12));
    assert!(close(u[mid], u0 + TAU, 1e-9), "{} vs {}", u[mid], u0 + TAU);
    assert!(close(u[n - 1], u0, 1e-9));
    assert!(u[..=mid].windows(2).all(|w| w[1] >= w[0]), "first pass goes forward");
    assert!(u[mid..].windows(2).all(|w| w[1] <= w[0]), "second pass goes back");
    // Rest at the ends: the first and last steps are much smaller than a cruise step.
    let cruise = (u[mid / 2 + 1] - u[mid / 2]).abs();
    assert!((u[1] - u[0]).abs() < 0.05 * cruise);
    assert!((u[n - 1] - u[n - 2]).abs() < 0.05 * cruise);
    // The relative positions of the second pass retrace the first.
    let rel = plan.trajectory.rel_pos_rtn_m.as_ref().expect("rel");
    for k in 0..=mid {
        let (a, b) = (rel[k], rel[n - 1 - k]);
        assert!((0..3).all(|i| close(a[i], b[i], 1e-6)), "{k}: {a:?} vs {b:?}");
    }
    // meta holds the orbit and the mapping.
    let meta: serde_json::Value =
        serde_json::from_str(plan.trajectory.meta.as_ref().expect("meta")).expect("json");
    for key in [
        "a_m",
        "e",
        "i_deg",
        "raan_deg",
        "argp_deg",
        "nu0_deg",
        "roe",
        "u0_rad",
        "scale",
        "target_pos_base_m",
        "rtn_to_base",
        "camera_mount",
        "preset",
        "range_m",
    ] {
        assert!(meta.get(key).is_some(), "meta lacks {key}");
    }
    assert_eq!(meta["roe"].as_array().map(|a| a.len()), Some(6));
    assert_eq!(meta["preset"], "flyaround");
    assert!(close(meta["roe"][2].as_f64().unwrap_or(0.0), 50.0 / 26_578_000.0, 1e-18));
}

#[test]
fn station_keeping_holds_one_pose() {
    let lab = LabConfig::default();
    let req = PlanRequest {
        preset: Preset::StationKeeping,
        range_m: 10.0,
        timing: Timing::DurationS(5.0),
        waypoints: Some(11),
        ..PlanRequest::default()
    };
    let plan = planner::plan(&req, &lab, &mut |_, _| {}).expect("plan");
    let q = &plan.trajectory.qpos;
    for k in 1..q.len() {
        assert!((0..7).all(|j| (q[k][j] - q[0][j]).abs() < 1e-9), "moved at {k}");
    }
    assert!(close(plan.summary.min_camera_target_m, 0.11 * 0.7, 1e-9));
}

#[test]
fn refuses_an_orbit_too_big_for_the_arm() {
    let lab = LabConfig::default();
    let req = PlanRequest { alpha: 1.0, waypoints: Some(20), revolutions: 1, ..short_flyaround() };
    match planner::plan(&req, &lab, &mut |_, _| {}) {
        Err(PlanError::DoesNotFit { message, .. }) => {
            assert!(message.contains("does not fit"), "{message}");
        }
        other => panic!("expected a refusal, got {:?}", other.map(|p| p.summary)),
    }
    let bad = PlanRequest { range_m: -1.0, ..short_flyaround() };
    assert!(matches!(planner::plan(&bad, &lab, &mut |_, _| {}), Err(PlanError::Request(_))));
    // A duration of 1e300 s overflowed the waypoint count (a panic in debug builds).
    let endless = PlanRequest {
        timing: planner::Timing::DurationS(1e300),
        waypoints: None,
        ..short_flyaround()
    };
    match planner::plan(&endless, &lab, &mut |_, _| {}) {
        Err(PlanError::Request(m)) => assert!(m.contains("waypoints"), "{m}"),
        other => panic!("expected a refusal, got {:?}", other.map(|p| p.summary)),
    }
}

#[test]
fn partial_orbit_names_the_feasible_arc_and_the_arc_plans() {
    let lab = LabConfig::default();
    // A rotation under which only part of the fly-around is reachable.
    let req = PlanRequest {
        rtn_rpy_deg: Some([0.0, 75.0, 180.0]),
        revolutions: 1,
        waypoints: Some(241),
        ..short_flyaround()
    };
    let Err(PlanError::DoesNotFit { message, feasible_arcs_deg }) =
        planner::plan(&req, &lab, &mut |_, _| {})
    else {
        panic!("expected a partial orbit");
    };
    assert!(message.contains("--arc"), "{message}");
    let (a, b) = feasible_arcs_deg[0];
    assert!(b - a > 10.0, "{feasible_arcs_deg:?}");
    let arc = PlanRequest { arc_deg: Some(((a + 2.0).ceil(), (b - 2.0).floor())), ..req };
    let plan = planner::plan(&arc, &lab, &mut |_, _| {}).expect("the offered arc plans");
    let u = plan.trajectory.u_rad.as_ref().expect("u");
    assert!(close(u[0].to_degrees(), (a + 2.0).ceil(), 1e-9));
}

#[test]
fn ik_tracks_with_warm_starts_and_reports_unreachable_poses() {
    let lab = LabConfig::default();
    let scene = Scene::from_lab(&lab);
    let mount = lab.camera_mount();
    let opts = IkOptions::default();
    let q0 = [-0.8, 0.2, -0.1, 1.3, 0.2, 1.0, 0.3];
    let goal = camera_pose(&q0, &mount);
    let sol = ik::solve(&goal, &[0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0], &mount, None, &opts);
    assert!(sol.converged && sol.pos_err_m < 1e-8, "{sol:?}");
    // Far outside the reach (2 m away): reported, not solved.
    let far = Isometry3::translation(2.0, 0.0, 0.5) * goal.rotation;
    let track = ik::track(&[goal, far], &q0, &mount, Some(&scene), &opts);
    assert!(track.q[0].is_ok(), "{:?}", track.q[0]);
    assert!(matches!(track.q[1], Err(ik::WaypointFailure::NotReached { .. })), "{:?}", track.q[1]);
}
