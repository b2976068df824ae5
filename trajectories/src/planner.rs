//! The orbital planner behind `hitl plan`: relative orbit (ROE, eq. (3)) -> scaled camera poses
//! in the arm-base frame -> xArm7 joint trajectory with its capture, light and Sun-phase channels.
//!
//! [`plan`] does the whole chain and returns the [`Trajectory`] with a [`PlanSummary`], or a
//! [`PlanError`] that says why the request cannot be met (bad request, or the scaled orbit does
//! not fit the arm's reachable, collision-free volume, with the feasible arcs when there are
//! some). Writing the NPZ and the preflight are the caller's (`hitl plan`).
//!
//! Everything is deterministic: the same request and lab give the same bytes (no clocks, no
//! hash-map iteration, a fixed seed order).

pub mod bench;
pub mod mapping;
mod meta;
pub use meta::rtn_to_base;
pub mod presets;
pub mod schedule;

use crate::ik::{self, IkOptions, Scene, WaypointFailure};
use crate::kinematics::{Joints, DOF};
use crate::lab::LabConfig;
use crate::orbit::{self, ChiefOrbit, Preset, Roe};
use crate::Trajectory;
use hitl_hal::Pose;
use mapping::{look_at, up_reference};
use nalgebra::{Matrix3, Point3, Vector3};
use schedule::Schedule;
use std::f64::consts::TAU;

/// How fast the orbit plays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Timing {
    /// Total playback duration in seconds (all passes, ramps included).
    DurationS(f64),
    /// Orbit time over playback time (the paper's tau, 500).
    TimeScale(f64),
}

/// Where the lab scale comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ScaleSource {
    /// The paper's workspace scale alpha * d_arm / range.
    Workspace,
    /// Printed model size over real target size (`lab.target.model_size_m`).
    Model,
}

/// Everything `hitl plan` can ask for. `Default` is the paper's 50 m fly-around at tau = 500.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanRequest {
    pub preset: Preset,
    /// Nominal range r, real metres.
    pub range_m: f64,
    pub timing: Timing,
    /// Number of waypoints; `None`: 10 per second of playback, plus one.
    pub waypoints: Option<usize>,
    /// Passes over the arc; the direction alternates after each (windup rule).
    pub revolutions: usize,
    /// Capture a frame at every k-th waypoint (waypoint 0 included).
    pub capture_every: usize,
    /// Light level for every waypoint, in [0, 1].
    pub light: f32,
    /// Ramp-up and ramp-down time of each pass, seconds (shortened to a third of a pass if needed).
    pub ramp_s: f64,
    /// Arc of argument of latitude to play, degrees (from, to) with from < to <= from + 360;
    /// `None`: the whole orbit from u0.
    pub arc_deg: Option<(f64, f64)>,
    /// RTN-to-base rotation as roll/pitch/yaw degrees (z-y-x); `None`: the documented default
    /// [`mapping::DEFAULT_RTN_TO_BASE`].
    pub rtn_rpy_deg: Option<[f64; 3]>,
    /// Sun direction in ECI.
    pub sun_eci: [f64; 3],
    pub alpha: f64,
    pub d_arm_m: f64,
    pub chief: ChiefOrbit,
}

impl Default for PlanRequest {
    fn default() -> Self {
        Self {
            preset: Preset::Flyaround,
            range_m: 50.0,
            timing: Timing::TimeScale(orbit::PAPER_TIME_SCALE),
            waypoints: None,
            revolutions: 1,
            capture_every: 1,
            light: 1.0,
            ramp_s: 2.0,
            arc_deg: None,
            rtn_rpy_deg: None,
            sun_eci: orbit::DEFAULT_SUN_ECI,
            alpha: mapping::PAPER_ALPHA,
            d_arm_m: mapping::PAPER_D_ARM_M,
            chief: ChiefOrbit::default(),
        }
    }
}

/// Waypoints per second of playback when `waypoints` is not given.
pub const DEFAULT_WAYPOINT_RATE_HZ: f64 = 10.0;
/// The most waypoints a plan may have.
pub const MAX_WAYPOINTS: usize = 200_000;

/// Why no plan was made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The request itself is invalid (a flag out of range).
    #[error("{0}")]
    Request(String),
    /// The scaled orbit does not fit the reachable, collision-free volume.
    #[error("{message}")]
    DoesNotFit {
        message: String,
        /// Feasible arcs of argument of latitude in degrees, longest first.
        feasible_arcs_deg: Vec<(f64, f64)>,
    },
}

/// What a plan looks like, for the CLI's summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PlanSummary {
    pub preset: String,
    pub range_m: f64,
    pub waypoints: usize,
    pub captures: usize,
    pub duration_s: f64,
    pub passes: usize,
    pub scale: f64,
    pub arc_deg: (f64, f64),
    pub min_camera_target_m: f64,
    pub max_camera_target_m: f64,
    pub peak_joint_speed_rad_s: [f64; DOF],
    pub max_ik_pos_err_m: f64,
    pub max_ik_rot_err_deg: f64,
    pub min_clearance_m: f64,
    pub sun_phase_deg: (f64, f64),
}

/// A plan: the trajectory to write and its summary.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub trajectory: Trajectory,
    pub summary: PlanSummary,
}

/// The orbital part of a plan, before IK: per waypoint time, u, RTN position, camera pose.
#[derive(Debug, Clone)]
pub struct OrbitPath {
    pub schedule: Schedule,
    pub roe: Roe,
    pub u0: f64,
    pub scale: f64,
    pub scale_source: ScaleSource,
    pub rtn_to_base: Matrix3<f64>,
    pub up_base: Vector3<f64>,
    pub target_base: Point3<f64>,
    pub t: Vec<f64>,
    pub u: Vec<f64>,
    pub pass: Vec<usize>,
    pub rel_rtn: Vec<Vector3<f64>>,
    pub cam_pose: Vec<Pose>,
}

fn request_error(m: impl Into<String>) -> PlanError {
    PlanError::Request(m.into())
}

fn check_request(req: &PlanRequest) -> Result<(), PlanError> {
    let pos = |name: &str, v: f64| {
        if v > 0.0 && v.is_finite() {
            Ok(())
        } else {
            Err(request_error(format!("{name} = {v} must be a positive number")))
        }
    };
    pos("--range-m", req.range_m)?;
    pos("--alpha", req.alpha)?;
    pos("--d-arm-m", req.d_arm_m)?;
    pos("chief a_m", req.chief.a_m)?;
    match req.timing {
        Timing::DurationS(d) => pos("--duration-s", d)?,
        Timing::TimeScale(s) => pos("--time-scale", s)?,
    }
    if !(req.ramp_s >= 0.0 && req.ramp_s.is_finite()) {
        return Err(request_error(format!("--ramp-s = {} must be zero or positive", req.ramp_s)));
    }
    if req.range_m > 0.01 * req.chief.a_m {
        return Err(request_error(format!(
            "--range-m {} m is not small against the chief's a = {} m: the first-order mapping \
             (eq. 3) does not hold",
            req.range_m, req.chief.a_m
        )));
    }
    if req.chief.e.abs() > 0.01 || !req.chief.e.is_finite() {
        return Err(request_error(format!(
            "chief eccentricity {} is not near-circular: eq. (3) assumes e ~ 0",
            req.chief.e
        )));
    }
    if req.revolutions == 0 || req.revolutions > 100 {
        return Err(request_error(format!("--revolutions {} must be 1-100", req.revolutions)));
    }
    if req.capture_every == 0 {
        return Err(request_error("--capture-every must be at least 1"));
    }
    if !(0.0..=1.0).contains(&req.light) {
        return Err(request_error(format!("--light {} must be in [0, 1]", req.light)));
    }
    if let Some(n) = req.waypoints {
        if !(2..=MAX_WAYPOINTS).contains(&n) {
            return Err(request_error(format!("--waypoints {n} must be 2-{MAX_WAYPOINTS}")));
        }
    }
    if let Some((a, b)) = req.arc_deg {
        if !(a.is_finite() && b.is_finite() && b > a && b - a <= 360.0) {
            return Err(request_error(format!(
                "--arc {a}:{b} must have FROM < TO <= FROM + 360 (degrees of argument of latitude)"
            )));
        }
    }
    let sun = Vector3::from(req.sun_eci);
    if !(sun.iter().all(|x| x.is_finite()) && sun.norm() > 0.0) {
        return Err(request_error("--sun-eci must be a non-zero finite vector"));
    }
    if req.rtn_rpy_deg.is_some_and(|r| r.iter().any(|x| !x.is_finite())) {
        return Err(request_error("--rtn-rpy-deg must be finite"));
    }
    Ok(())
}

/// The scale (lab metres per real metre) and where it came from.
pub fn scale_for(req: &PlanRequest, lab: &LabConfig) -> (f64, ScaleSource) {
    match lab.target.model_size_m {
        Some(m) => (m / lab.target.real_size_m, ScaleSource::Model),
        None => {
            (mapping::workspace_scale(req.alpha, req.d_arm_m, req.range_m), ScaleSource::Workspace)
        }
    }
}

/// Build the orbital path and camera poses (everything but IK).
pub fn orbit_path(req: &PlanRequest, lab: &LabConfig) -> Result<OrbitPath, PlanError> {
    check_request(req)?;
    let chief = &req.chief;
    let a = chief.a_m;
    let roe = req.preset.roe(req.range_m, a);
    let u0 = chief.u0_rad();
    let (u_start, span) = match req.arc_deg {
        Some((from, to)) => (from.to_radians(), (to - from).to_radians()),
        None => (u0, TAU),
    };
    let n = chief.mean_motion();
    let passes = req.revolutions;
    let schedule = match req.timing {
        Timing::TimeScale(tau) => {
            let cruise = span / (n * tau);
            Schedule { u_start, span, passes, cruise_s: cruise, ramp_s: req.ramp_s.min(cruise) }
        }
        Timing::DurationS(d) => {
            let pass = d / passes as f64;
            let ramp = req.ramp_s.min(pass / 3.0);
            Schedule { u_start, span, passes, cruise_s: pass - ramp, ramp_s: ramp }
        }
    };
    let duration = schedule.duration_s();
    let count = match req.waypoints {
        Some(c) => c,
        // Saturating: a duration of 1e300 s is refused below by the count, not by an overflow.
        None => ((duration * DEFAULT_WAYPOINT_RATE_HZ).round() as usize).saturating_add(1),
    };
    if !(2..=MAX_WAYPOINTS).contains(&count) {
        return Err(request_error(format!(
            "{count} waypoints for {duration:.1} s: choose --waypoints or --duration-s so there are 2-{MAX_WAYPOINTS}"
        )));
    }
    let (scale, scale_source) = scale_for(req, lab);
    let rtn_to_base = match &req.rtn_rpy_deg {
        Some(rpy) => mapping::rotation_from_rpy_deg(rpy),
        None => mapping::default_rtn_to_base(),
    };
    let target_base = lab.target_position_base();

    // The up reference comes from the arc's shape, sampled finely once (not from the waypoints,
    // so it does not depend on their count).
    let shape: Vec<Vector3<f64>> =
        (0..=720).map(|k| roe.position_rtn(a, u_start + span * k as f64 / 720.0, u0)).collect();
    let up_base = up_reference(&shape, &rtn_to_base);

    let t = schedule.times(count);
    let mut u = Vec::with_capacity(count);
    let mut pass = Vec::with_capacity(count);
    let mut rel_rtn = Vec::with_capacity(count);
    let mut cam_pose = Vec::with_capacity(count);
    for &tk in &t {
        let (uk, pk) = schedule.u_at(tk);
        let rel = roe.position_rtn(a, uk, u0);
        let position = target_base + scale * (rtn_to_base * rel);
        let Some(pose) = look_at(&position, &target_base, &up_base) else {
            return Err(PlanError::DoesNotFit {
                message: format!(
                    "at u = {:.1} deg the camera would look along its up reference (or sit on the \
                     target): choose another --rtn-rpy-deg",
                    orbit::wrapped_deg(uk)
                ),
                feasible_arcs_deg: vec![],
            });
        };
        u.push(uk);
        pass.push(pk);
        rel_rtn.push(rel);
        cam_pose.push(pose);
    }
    Ok(OrbitPath {
        schedule,
        roe,
        u0,
        scale,
        scale_source,
        rtn_to_base,
        up_base,
        target_base,
        t,
        u,
        pass,
        rel_rtn,
        cam_pose,
    })
}

/// How many candidate first solutions are tracked through the whole path.
const TRACKED_SEEDS: usize = 4;

/// Solve the camera poses of `path` for the arm, trying the best few first solutions (lowest
/// secondary cost first) and keeping the first track that solves every waypoint, else the one
/// that solves most (then the lowest cost). `progress(done, total)` is called
/// after each tracked candidate.
pub fn solve_path(
    path: &OrbitPath,
    lab: &LabConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ik::Track, PlanError> {
    let scene = Scene::from_lab(lab);
    let mount = lab.camera_mount();
    let opts = IkOptions::for_lab(lab);
    let first = ik::solve_from_seeds(&path.cam_pose[0], &mount, Some(&scene), &opts, TRACKED_SEEDS);
    let mut best: Option<ik::Track> = None;
    let total = first.len();
    for (k, seed) in first.iter().enumerate() {
        let track = ik::track(&path.cam_pose, seed, &mount, Some(&scene), &opts);
        let better = match &best {
            None => true,
            Some(b) => {
                track.solved() > b.solved() || (track.solved() == b.solved() && track.cost < b.cost)
            }
        };
        if better {
            best = Some(track);
        }
        progress(k + 1, total);
        if best.as_ref().is_some_and(|b| b.solved() == path.cam_pose.len()) {
            break;
        }
    }
    best.ok_or_else(|| does_not_fit(path, None, &scene, &mount, &opts))
}

/// The feasible arcs of the first pass (degrees of u), longest first.
fn feasible_arcs(path: &OrbitPath, ok: &[bool]) -> Vec<(f64, f64)> {
    let mut arcs = Vec::new();
    let mut start: Option<usize> = None;
    let first_pass: Vec<usize> = (0..ok.len()).filter(|&i| path.pass[i] == 0).collect();
    for (j, &i) in first_pass.iter().enumerate() {
        if ok[i] {
            start.get_or_insert(j);
        }
        let end_here = !ok[i] || j + 1 == first_pass.len();
        if end_here {
            if let Some(s) = start.take() {
                let e = if ok[i] { j } else { j - 1 };
                if e > s {
                    let a = path.u[first_pass[s]].to_degrees();
                    let b = path.u[first_pass[e]].to_degrees();
                    arcs.push((a.min(b), a.max(b)));
                }
            }
        }
    }
    arcs.sort_by(|x, y| (y.1 - y.0).total_cmp(&(x.1 - x.0)));
    arcs
}

fn does_not_fit(
    path: &OrbitPath,
    track: Option<&ik::Track>,
    scene: &Scene,
    mount: &Pose,
    opts: &IkOptions,
) -> PlanError {
    let max_range = path
        .cam_pose
        .iter()
        .map(|p| (p.translation.vector - path.target_base.coords).norm())
        .fold(0.0, f64::max);
    let what = format!(
        "the scaled orbit (scale {:.3e}, camera up to {:.3} m from the target) does not fit the \
         arm's reachable, collision-free volume",
        path.scale, max_range
    );
    let Some(track) = track else {
        // Not even the first waypoint: say why, from the best effort at it.
        let sol = ik::solve(
            &path.cam_pose[0],
            &[0.0, 0.0, 0.0, 1.2, 0.0, 1.2, 0.0],
            mount,
            Some(scene),
            opts,
        );
        let why = if sol.converged {
            format!("{}", WaypointFailure::Clearance(scene.nearest(&sol.q)))
        } else {
            format!(
                "{}",
                WaypointFailure::NotReached {
                    pos_err_m: sol.pos_err_m,
                    rot_err_deg: sol.rot_err_rad.to_degrees()
                }
            )
        };
        return PlanError::DoesNotFit {
            message: format!(
                "{what}: no collision-free joint solution at the first waypoint ({why}); try a \
                 smaller --alpha, another --rtn-rpy-deg or move the target in the lab config"
            ),
            feasible_arcs_deg: vec![],
        };
    };
    let ok: Vec<bool> = track.q.iter().map(|r| r.is_ok()).collect();
    let arcs = feasible_arcs(path, &ok);
    let (first_bad, reason) = track
        .q
        .iter()
        .enumerate()
        .find_map(|(i, r)| r.as_ref().err().map(|e| (i, e.to_string())))
        .unwrap_or((0, String::new()));
    let bad = ok.iter().filter(|x| !**x).count();
    let mut message = format!(
        "{what}: {bad} of {} waypoints have no acceptable joint solution; first at waypoint {} \
         (u = {:.1} deg): {reason}",
        ok.len(),
        first_bad,
        path.u[first_bad].to_degrees()
    );
    match arcs.first() {
        Some(&(a, b)) if b - a > 10.0 => {
            // Offer the longest arc, 2 degrees in from each end.
            message.push_str(&format!(
                "\nfeasible arcs of u (deg): {}\nthe longest can be planned with: --arc {:.0}:{:.0}",
                arcs.iter().map(|(a, b)| format!("{a:.1}-{b:.1}")).collect::<Vec<_>>().join(", "),
                (a + 2.0).ceil(),
                (b - 2.0).floor()
            ));
        }
        _ => message.push_str("\nno usable arc of the orbit is feasible"),
    }
    PlanError::DoesNotFit { message, feasible_arcs_deg: arcs }
}

/// Plan the whole trajectory. `progress(done, total)` reports IK progress.
pub fn plan(
    req: &PlanRequest,
    lab: &LabConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Plan, PlanError> {
    let path = orbit_path(req, lab)?;
    let track = solve_path(&path, lab, progress)?;
    if track.solved() < path.cam_pose.len() {
        let scene = Scene::from_lab(lab);
        let opts =
            IkOptions { limit_margin_rad: lab.margins.joint_limit_rad, ..IkOptions::default() };
        return Err(does_not_fit(&path, Some(&track), &scene, &lab.camera_mount(), &opts));
    }
    let qpos: Vec<Joints> = track.q.iter().filter_map(|r| r.as_ref().ok().copied()).collect();
    Ok(assemble(req, lab, &path, &track, qpos))
}

fn assemble(
    req: &PlanRequest,
    lab: &LabConfig,
    path: &OrbitPath,
    track: &ik::Track,
    qpos: Vec<Joints>,
) -> Plan {
    let n = qpos.len();
    let sun = Vector3::from(req.sun_eci);
    let sun_phase: Vec<f64> = path
        .u
        .iter()
        .zip(&path.rel_rtn)
        .map(|(u, r)| orbit::sun_phase_deg(&req.chief, *u, r, &sun).unwrap_or(0.0))
        .collect();
    let capture: Vec<bool> = (0..n).map(|k| k % req.capture_every == 0).collect();
    let cam: Vec<[[f64; 4]; 4]> = path.cam_pose.iter().map(pose_rows).collect();
    let mut peak = [0.0; DOF];
    for k in 1..n {
        let dt = path.t[k] - path.t[k - 1];
        for j in 0..DOF {
            peak[j] = f64::max(peak[j], (qpos[k][j] - qpos[k - 1][j]).abs() / dt);
        }
    }
    let scene = Scene::from_lab(lab);
    let min_clearance =
        qpos.iter().map(|q| scene.nearest(q).clearance_m).fold(f64::INFINITY, f64::min);
    let ranges: Vec<f64> = path
        .cam_pose
        .iter()
        .map(|p| (p.translation.vector - path.target_base.coords).norm())
        .collect();
    let (u_lo, u_hi) = (
        path.schedule.u_start.to_degrees(),
        (path.schedule.u_start + path.schedule.span).to_degrees(),
    );
    let summary = PlanSummary {
        preset: req.preset.name().to_string(),
        range_m: req.range_m,
        waypoints: n,
        captures: capture.iter().filter(|c| **c).count(),
        duration_s: path.schedule.duration_s(),
        passes: path.schedule.passes,
        scale: path.scale,
        arc_deg: (u_lo, u_hi),
        min_camera_target_m: ranges.iter().copied().fold(f64::INFINITY, f64::min),
        max_camera_target_m: ranges.iter().copied().fold(0.0, f64::max),
        peak_joint_speed_rad_s: peak,
        max_ik_pos_err_m: track.max_pos_err_m,
        max_ik_rot_err_deg: track.max_rot_err_rad.to_degrees(),
        min_clearance_m: min_clearance,
        sun_phase_deg: (
            sun_phase.iter().copied().fold(f64::INFINITY, f64::min),
            sun_phase.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ),
    };
    let meta = meta::meta_json(req, lab, path);
    let trajectory = Trajectory {
        qpos,
        t: path.t.clone(),
        capture: Some(capture),
        light: Some(vec![req.light; n]),
        u_rad: Some(path.u.clone()),
        rel_pos_rtn_m: Some(path.rel_rtn.iter().map(|v| [v.x, v.y, v.z]).collect()),
        cam_pose_base: Some(cam),
        sun_phase_deg: Some(sun_phase),
        meta: Some(meta),
    };
    Plan { trajectory, summary }
}

/// A pose as a row-major 4x4 matrix.
pub fn pose_rows(p: &Pose) -> [[f64; 4]; 4] {
    let m = p.to_homogeneous();
    let mut out = [[0.0; 4]; 4];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = m[(r, c)];
        }
    }
    out
}
