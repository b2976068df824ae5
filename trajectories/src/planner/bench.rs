//! The IK benchmark (`hitl bench ik`): the planner's solver on a fly-around of many waypoints in
//! the default lab, timed, with its accuracy measured by forward kinematics.
//! `scripts/bench_ik.py` solves the same poses (from `hitl plan --waypoints N`) with ikpy.

use super::{orbit_path, PlanRequest, Timing};
use crate::ik::{self, IkOptions, Scene};
use crate::kinematics::camera_pose;
use crate::lab::LabConfig;
use serde_json::json;
use std::time::Instant;

/// The request whose camera poses the benchmark solves (`hitl plan --preset flyaround
/// --duration-s 60 --waypoints N` makes the same poses for `scripts/bench_ik.py`).
pub fn bench_request(waypoints: usize) -> PlanRequest {
    PlanRequest {
        waypoints: Some(waypoints.max(2)),
        timing: Timing::DurationS(60.0),
        ..PlanRequest::default()
    }
}

/// Time the IK of a one-revolution 50 m fly-around with `waypoints` waypoints (the default lab,
/// 60 s playback). Returns figures as JSON: seed search and tracking times, per-waypoint time,
/// iterations, and the worst FK residuals of the solutions.
pub fn bench_ik(waypoints: usize) -> serde_json::Value {
    let lab = LabConfig::default();
    let req = bench_request(waypoints);
    let path = match orbit_path(&req, &lab) {
        Ok(p) => p,
        Err(e) => return json!({ "error": e.to_string() }),
    };
    let scene = Scene::from_lab(&lab);
    let mount = lab.camera_mount();
    let opts = IkOptions::for_lab(&lab);
    let t0 = Instant::now();
    let seeds = ik::solve_from_seeds(&path.cam_pose[0], &mount, Some(&scene), &opts, 1);
    let seed_s = t0.elapsed().as_secs_f64();
    let Some(seed) = seeds.first() else {
        return json!({ "error": "no solution at the first waypoint" });
    };
    // Tracking with the obstacle penalty (what the planner does) and without (pure IK).
    let t1 = Instant::now();
    let track = ik::track(&path.cam_pose, seed, &mount, Some(&scene), &opts);
    let track_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let bare = ik::track(&path.cam_pose, seed, &mount, None, &opts);
    let bare_s = t2.elapsed().as_secs_f64();
    let (mut pos, mut rot) = (0.0f64, 0.0f64);
    for (r, target) in track.q.iter().zip(&path.cam_pose) {
        if let Ok(q) = r {
            let e = ik::pose_error(target, &camera_pose(q, &mount));
            pos = pos.max(e.fixed_rows::<3>(0).norm());
            rot = rot.max(e.fixed_rows::<3>(3).norm());
        }
    }
    let n = path.cam_pose.len();
    json!({
        "bench": "ik",
        "waypoints": n,
        "solved": track.solved(),
        "seed_search_s": seed_s,
        "track_s": track_s,
        "track_us_per_waypoint": track_s * 1e6 / n as f64,
        "track_no_obstacles_s": bare_s,
        "track_no_obstacles_solved": bare.solved(),
        "track_no_obstacles_us_per_waypoint": bare_s * 1e6 / n as f64,
        "iterations_per_waypoint": track.iterations as f64 / n as f64,
        "max_pos_err_m": pos,
        "max_rot_err_deg": rot.to_degrees(),
    })
}
