//! Inverse kinematics of the xArm7 with its camera: damped least squares on the geometric
//! Jacobian of the camera frame, with the arm's one redundant degree of freedom spent (in the
//! Jacobian's null space) on staying away from joint limits and from the scene's obstacles.
//!
//! A solve is two phases: a few steps that track the pose while descending the secondary cost
//! in the null space, then plain damped Newton steps until the camera pose is met to
//! [`IkOptions::pos_tol_m`] and [`IkOptions::rot_tol_rad`]. Joint values are clamped to the
//! limits shrunk by the margin at every step, so a converged solution is inside them.
//! [`track`] solves a sequence of poses, warm-starting each from the previous solution so the arm
//! stays on one branch; a step larger than [`IkOptions::max_waypoint_step_rad`] is reported as a
//! branch jump, never silently kept.

mod clearance;

pub use clearance::{Nearest, Scene, SELF_MARGIN_M};

use crate::joint_table::JointTable;
use crate::kinematics::{camera_pose, link_frames, Joints, DOF};
use crate::lab::LabConfig;
use hitl_hal::Pose;
use nalgebra::{Matrix6, SMatrix, SVector, Vector3, Vector6};
use std::f64::consts::{FRAC_PI_2, PI};

/// The 6x7 geometric Jacobian: rows are linear (x, y, z) then angular (x, y, z) velocity of the
/// camera frame in the base frame, per unit joint speed.
pub type Jacobian = SMatrix<f64, 6, DOF>;

/// Tuning of the solver. `Default` is what the planner uses.
#[derive(Debug, Clone, PartialEq)]
pub struct IkOptions {
    /// The joint-limit table solutions must stay inside.
    pub joint_table: JointTable,
    /// Distance kept from every joint limit, radians.
    pub limit_margin_rad: f64,
    /// Position tolerance, metres.
    pub pos_tol_m: f64,
    /// Orientation tolerance, radians.
    pub rot_tol_rad: f64,
    /// Most iterations per solve.
    pub max_iters: usize,
    /// Null-space steps per solve (phase 1).
    pub null_steps: usize,
    /// Gain on the secondary-cost gradient in the null space.
    pub null_gain: f64,
    /// Clearance under which the obstacle penalty starts, metres.
    pub activation_m: f64,
    /// Weight of the obstacle penalty against the joint-limit cost.
    pub clearance_weight: f64,
    /// Largest joint change per iteration, radians.
    pub max_iter_step_rad: f64,
    /// Largest joint change between successive waypoints before it counts as a branch jump.
    pub max_waypoint_step_rad: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        Self {
            joint_table: JointTable::default(),
            limit_margin_rad: 0.05,
            pos_tol_m: 1e-10,
            rot_tol_rad: 1e-10,
            max_iters: 200,
            null_steps: 2,
            null_gain: 0.05,
            activation_m: 0.06,
            clearance_weight: 4.0,
            max_iter_step_rad: 0.25,
            max_waypoint_step_rad: 0.25,
        }
    }
}

impl IkOptions {
    /// The defaults, inside `lab`'s joint table and joint-limit margin.
    pub fn for_lab(lab: &LabConfig) -> Self {
        Self {
            joint_table: lab.arm.joint_table,
            limit_margin_rad: lab.margins.joint_limit_rad,
            ..Self::default()
        }
    }
}

/// Camera pose and its geometric Jacobian at `q`.
pub fn camera_jacobian(q: &Joints, mount: &Pose) -> (Pose, Jacobian) {
    let f = link_frames(q);
    let cam = f[DOF] * mount;
    let p = cam.translation.vector;
    let mut j = Jacobian::zeros();
    for i in 0..DOF {
        let z = f[i + 1].rotation * Vector3::z();
        let o = f[i + 1].translation.vector;
        let v = z.cross(&(p - o));
        j.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
        j.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
    }
    (cam, j)
}

/// Pose error `target - current` as (position, rotation vector), both in the base frame.
pub fn pose_error(target: &Pose, current: &Pose) -> Vector6<f64> {
    let dp = target.translation.vector - current.translation.vector;
    let dr = (target.rotation * current.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Centres and half-ranges of the joints for the limit cost. The unlimited (+-2 pi) joints are
/// pulled weakly toward 0 so they never wind up toward their stops.
fn limit_cost_gradient(q: &Joints, limits: &[(f64, f64); DOF]) -> SVector<f64, DOF> {
    let mut g = SVector::<f64, DOF>::zeros();
    for i in 0..DOF {
        let (lo, hi) = limits[i];
        let mid = 0.5 * (lo + hi);
        let half = 0.5 * (hi - lo);
        let weight = if hi - lo > 3.0 * PI { 0.1 } else { 1.0 };
        g[i] = weight * 2.0 * (q[i] - mid) / (half * half);
    }
    let x = q[WRIST] / WRIST_WIDTH_RAD;
    g[WRIST] += WRIST_WEIGHT * (-x * x).exp() * (-2.0 * x / WRIST_WIDTH_RAD);
    g
}

/// Joint 6 (index 5): at 0 the wrist is straight and joints 5 and 7 align (a singularity where
/// they would spin fast). The secondary cost adds a bump of this weight and width around it.
const WRIST: usize = 5;
const WRIST_WEIGHT: f64 = 2.0;
const WRIST_WIDTH_RAD: f64 = 0.5;

/// The secondary cost's value: joint-limit cost plus weighted obstacle penalty.
pub fn secondary_cost(q: &Joints, scene: Option<&Scene>, opts: &IkOptions) -> f64 {
    let mut c = 0.0;
    let limits = opts.joint_table.limits();
    for i in 0..DOF {
        let (lo, hi) = limits[i];
        let mid = 0.5 * (lo + hi);
        let half = 0.5 * (hi - lo);
        let weight = if hi - lo > 3.0 * PI { 0.1 } else { 1.0 };
        c += weight * ((q[i] - mid) / half).powi(2);
    }
    c += WRIST_WEIGHT * (-(q[WRIST] / WRIST_WIDTH_RAD).powi(2)).exp();
    if let Some(s) = scene {
        c += opts.clearance_weight * s.penalty(q, opts.activation_m);
    }
    c
}

fn secondary_gradient(q: &Joints, scene: Option<&Scene>, opts: &IkOptions) -> SVector<f64, DOF> {
    let mut g = limit_cost_gradient(q, &opts.joint_table.limits());
    if let Some(s) = scene {
        let p0 = s.penalty(q, opts.activation_m);
        if p0 > 0.0 {
            const H: f64 = 1e-5;
            for i in 0..DOF {
                let mut qh = *q;
                qh[i] += H;
                g[i] += opts.clearance_weight * (s.penalty(&qh, opts.activation_m) - p0) / H;
            }
        }
    }
    g
}

/// One solve's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct IkSolution {
    pub q: Joints,
    pub pos_err_m: f64,
    pub rot_err_rad: f64,
    pub iterations: usize,
    pub converged: bool,
}

fn clamp_to_limits(q: &mut Joints, limits: &[(f64, f64); DOF], margin: f64) {
    for i in 0..DOF {
        let (lo, hi) = limits[i];
        q[i] = q[i].clamp(lo + margin, hi - margin);
    }
}

/// Solve for the camera pose `target` from `seed`.
pub fn solve(
    target: &Pose,
    seed: &Joints,
    mount: &Pose,
    scene: Option<&Scene>,
    opts: &IkOptions,
) -> IkSolution {
    let mut q = *seed;
    clamp_to_limits(&mut q, &opts.joint_table.limits(), opts.limit_margin_rad);
    for it in 0..opts.max_iters {
        let (cam, j) = camera_jacobian(&q, mount);
        let e = pose_error(target, &cam);
        let pe = e.fixed_rows::<3>(0).norm();
        let re = e.fixed_rows::<3>(3).norm();
        let null_phase = it < opts.null_steps;
        if !null_phase && pe < opts.pos_tol_m && re < opts.rot_tol_rad {
            return IkSolution {
                q,
                pos_err_m: pe,
                rot_err_rad: re,
                iterations: it,
                converged: true,
            };
        }
        // Damping grows with the error: Newton near the solution, robust far from it.
        let lambda2 = 1e-9 + 1e-3 * e.norm_squared().min(1.0);
        let jjt: Matrix6<f64> = j * j.transpose() + Matrix6::identity() * lambda2;
        let Some(chol) = jjt.cholesky() else {
            break;
        };
        let mut dq: SVector<f64, DOF> = j.transpose() * chol.solve(&e);
        if null_phase {
            // Null-space projector of the damped pseudo-inverse: I - J^T (J J^T)^-1 J.
            let jpinv_j = j.transpose() * chol.solve(&j);
            let proj = SMatrix::<f64, DOF, DOF>::identity() - jpinv_j;
            let g = secondary_gradient(&q, scene, opts);
            dq -= proj * g * opts.null_gain;
        }
        let n = dq.amax();
        if n > opts.max_iter_step_rad {
            dq *= opts.max_iter_step_rad / n;
        }
        for i in 0..DOF {
            q[i] += dq[i];
        }
        clamp_to_limits(&mut q, &opts.joint_table.limits(), opts.limit_margin_rad);
    }
    let (cam, _) = camera_jacobian(&q, mount);
    let e = pose_error(target, &cam);
    let pe = e.fixed_rows::<3>(0).norm();
    let re = e.fixed_rows::<3>(3).norm();
    IkSolution {
        q,
        pos_err_m: pe,
        rot_err_rad: re,
        iterations: opts.max_iters,
        converged: pe < opts.pos_tol_m && re < opts.rot_tol_rad,
    }
}

/// Why a waypoint has no acceptable joint solution.
#[derive(Debug, Clone, PartialEq)]
pub enum WaypointFailure {
    /// The solver did not meet the pose (out of reach, or only reachable past a joint limit).
    NotReached { pos_err_m: f64, rot_err_deg: f64 },
    /// The pose is met but the arm comes too close to something.
    Clearance(Nearest),
    /// The solution is a different branch from the previous waypoint's.
    BranchJump { joint: usize, step_rad: f64 },
}

impl std::fmt::Display for WaypointFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WaypointFailure::NotReached { pos_err_m, rot_err_deg } => write!(
                f,
                "camera pose not reachable within joint limits (left {:.1} mm, {:.2} deg off)",
                pos_err_m * 1e3,
                rot_err_deg
            ),
            WaypointFailure::Clearance(n) => write!(
                f,
                "{} would come {:.1} mm inside the margin around {}",
                n.part,
                -n.clearance_m * 1e3,
                n.obstacle
            ),
            WaypointFailure::BranchJump { joint, step_rad } => write!(
                f,
                "joint {} would jump {:.1} deg between waypoints (IK branch change)",
                joint + 1,
                step_rad.to_degrees()
            ),
        }
    }
}

/// A sequence solve: per waypoint, the joints or why not.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    pub q: Vec<Result<Joints, WaypointFailure>>,
    /// Total solver iterations (for benchmarks).
    pub iterations: usize,
    /// Largest position and orientation residuals over the solved waypoints.
    pub max_pos_err_m: f64,
    pub max_rot_err_rad: f64,
    /// Sum of the secondary cost over solved waypoints (to compare seeds).
    pub cost: f64,
}

impl Track {
    pub fn solved(&self) -> usize {
        self.q.iter().filter(|r| r.is_ok()).count()
    }
}

/// Check one converged solution against the scene and the previous waypoint.
fn accept(
    sol: &IkSolution,
    prev: Option<&Joints>,
    scene: Option<&Scene>,
    opts: &IkOptions,
) -> Result<(), WaypointFailure> {
    if !sol.converged {
        return Err(WaypointFailure::NotReached {
            pos_err_m: sol.pos_err_m,
            rot_err_deg: sol.rot_err_rad.to_degrees(),
        });
    }
    if let Some(p) = prev {
        let (joint, step) = (0..DOF)
            .map(|i| (i, (sol.q[i] - p[i]).abs()))
            .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        if step > opts.max_waypoint_step_rad {
            return Err(WaypointFailure::BranchJump { joint, step_rad: step });
        }
    }
    if let Some(s) = scene {
        let n = s.nearest(&sol.q);
        if n.clearance_m < 0.0 {
            return Err(WaypointFailure::Clearance(n));
        }
    }
    Ok(())
}

/// Sub-steps used to follow the branch when a waypoint's direct solution moves a joint by more
/// than [`IkOptions::max_waypoint_step_rad`].
const MARCH_STEPS: usize = 8;

/// Solve `target` from the previous solution `prev` (at pose `prev_pose`) by marching through
/// interpolated poses, so the solution stays on `prev`'s branch even for a large waypoint step.
fn march(
    prev_pose: &Pose,
    target: &Pose,
    prev: &Joints,
    mount: &Pose,
    scene: Option<&Scene>,
    opts: &IkOptions,
) -> (IkSolution, usize) {
    let mut q = *prev;
    let mut iterations = 0;
    for k in 1..=MARCH_STEPS {
        let s = k as f64 / MARCH_STEPS as f64;
        let pose = prev_pose.lerp_slerp(target, s);
        let sol = solve(&pose, &q, mount, scene, opts);
        iterations += sol.iterations;
        let step = (0..DOF).map(|i| (sol.q[i] - q[i]).abs()).fold(0.0, f64::max);
        if !sol.converged || step > opts.max_waypoint_step_rad {
            return (sol, iterations);
        }
        q = sol.q;
        if k == MARCH_STEPS {
            return (sol, iterations);
        }
    }
    (solve(target, &q, mount, scene, opts), iterations)
}

/// How far a camera pose moves: translation plus rotation times a 0.1 m lever.
fn pose_step(a: &Pose, b: &Pose) -> f64 {
    let e = pose_error(b, a);
    e.fixed_rows::<3>(0).norm() + 0.1 * e.fixed_rows::<3>(3).norm()
}

/// Solve `poses` in order from `seed`, each warm-started from the previous solution. A waypoint
/// whose pose equals the previous one keeps the previous joints exactly (a held pose does not
/// drift along the self-motion). A large joint step is re-solved by marching through
/// interpolated poses; only a step that stays large is a branch jump. After a failed waypoint
/// the next one starts again from the last good solution (or the seed).
pub fn track(
    poses: &[Pose],
    seed: &Joints,
    mount: &Pose,
    scene: Option<&Scene>,
    opts: &IkOptions,
) -> Track {
    let mut out = Track {
        q: Vec::with_capacity(poses.len()),
        iterations: 0,
        max_pos_err_m: 0.0,
        max_rot_err_rad: 0.0,
        cost: 0.0,
    };
    let mut warm = *seed;
    let mut prev: Option<(Joints, Pose)> = None;
    // The self-motion per waypoint is scaled by how far the pose moves (against the path's
    // largest step), so the arm comes to rest with the pose at rest-to-rest ends.
    let steps: Vec<f64> =
        std::iter::once(0.0).chain(poses.windows(2).map(|w| pose_step(&w[0], &w[1]))).collect();
    let largest = steps.iter().copied().fold(0.0, f64::max);
    for (k, pose) in poses.iter().enumerate() {
        let weight = if largest > 0.0 { steps[k] / largest } else { 0.0 };
        let scaled = IkOptions { null_gain: opts.null_gain * weight, ..opts.clone() };
        let opts = &scaled;
        if let Some((q, p)) = &prev {
            if p == pose {
                out.cost += secondary_cost(q, scene, opts);
                out.q.push(Ok(*q));
                continue;
            }
        }
        let mut sol = solve(pose, &warm, mount, scene, opts);
        out.iterations += sol.iterations;
        if let Some((q, p)) = &prev {
            let step = (0..DOF).map(|i| (sol.q[i] - q[i]).abs()).fold(0.0, f64::max);
            if sol.converged && step > opts.max_waypoint_step_rad {
                let (marched, iters) = march(p, pose, q, mount, scene, opts);
                out.iterations += iters;
                sol = marched;
            }
        }
        match accept(&sol, prev.as_ref().map(|(q, _)| q), scene, opts) {
            Ok(()) => {
                out.max_pos_err_m = out.max_pos_err_m.max(sol.pos_err_m);
                out.max_rot_err_rad = out.max_rot_err_rad.max(sol.rot_err_rad);
                out.cost += secondary_cost(&sol.q, scene, opts);
                warm = sol.q;
                prev = Some((sol.q, *pose));
                out.q.push(Ok(sol.q));
            }
            Err(e) => {
                // A jump or failure breaks continuity: the next good waypoint starts a new arc.
                prev = None;
                out.q.push(Err(e));
            }
        }
    }
    out
}

/// Deterministic seeds for the first waypoint: elbow and wrist bends around a forward-reaching
/// posture, shoulder yawed toward the goal.
pub fn seeds(goal: &Pose) -> Vec<Joints> {
    let p = goal.translation.vector;
    let yaw = p.y.atan2(p.x);
    let mut out = Vec::new();
    for j2 in [0.0, 0.6] {
        for j4 in [0.8, 1.6, 2.4] {
            for j5 in [0.0, FRAC_PI_2, -FRAC_PI_2, PI] {
                for j6 in [0.5, 1.5] {
                    out.push([yaw, j2, 0.0, j4, j5, j6, 0.0]);
                }
            }
        }
    }
    out
}

/// Converged, clear, distinct solutions of one pose from [`seeds`], best secondary cost first.
/// The `keep` best are then refined along their self-motion (many null-space steps) so that the
/// arm starts near the redundancy optimum and barely drifts while the pose is still at rest.
pub fn solve_from_seeds(
    target: &Pose,
    mount: &Pose,
    scene: Option<&Scene>,
    opts: &IkOptions,
    keep: usize,
) -> Vec<Joints> {
    let mut found: Vec<(f64, Joints)> = Vec::new();
    let quick = IkOptions { null_steps: 10, ..opts.clone() };
    for s in seeds(target) {
        let sol = solve(target, &s, mount, scene, &quick);
        if accept(&sol, None, scene, opts).is_err() {
            continue;
        }
        if found.iter().any(|(_, q)| (0..DOF).all(|i| (q[i] - sol.q[i]).abs() < 0.05)) {
            continue;
        }
        found.push((secondary_cost(&sol.q, scene, opts), sol.q));
    }
    found.sort_by(|a, b| a.0.total_cmp(&b.0));
    let deep = IkOptions { null_steps: 150, ..opts.clone() };
    found
        .into_iter()
        .take(keep)
        .map(|(_, q)| {
            let sol = solve(target, &q, mount, scene, &deep);
            if accept(&sol, None, scene, opts).is_ok() {
                sol.q
            } else {
                q
            }
        })
        .collect()
}

/// Forward check of a solution: camera pose at `q` (for tests and reports).
pub fn camera_at(q: &Joints, mount: &Pose) -> Pose {
    camera_pose(q, mount)
}
