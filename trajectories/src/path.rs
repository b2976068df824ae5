//! Collision-free joint-space paths around the lab's obstacles, for the moves `hitl` plans before
//! anything moves: the approach to a trajectory's first setpoint, the retreat to the rest pose,
//! `hitl park`.
//!
//! A pose is free when it keeps every clearance the preflight checks (the arm's capsules to the
//! enclosure's faces and to the target, tripod and light keep-outs, the camera to the target
//! centre: [`Obstacles::at`], the preflight's own geometry) by a small planning buffer more, and
//! every joint inside the lab's joint table less its margin. The planner is RRT-Connect (Kuffner
//! and LaValle, 2000; the `rrt` crate's `dual_rrt_connect`) in joint space, sampled by a seeded
//! ChaCha8 generator, its path checked edge by edge at a fine step and then shortened by random
//! shortcutting (as OMPL's and MoveIt's path simplifiers do; seeded too) and a greedy pass. Every
//! step is deterministic: the same start, goal and lab give the same path. The path is a list of
//! waypoints joined by straight lines in joint space; the caller time-parametrises it and runs
//! the full preflight over every tick.

use crate::kinematics::{Joints, CAPSULE_NAMES, DOF};
use crate::lab::LabConfig;
use crate::preflight::{Obstacles, FACE_NAMES};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::cell::RefCell;

/// How the planner searches. `Default` is what `hitl` uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathOptions {
    /// Seed of the first attempt; attempt `i` uses `seed + i`.
    pub seed: u64,
    /// Attempts, each a fresh RRT-Connect search: the first two sample near the start and goal
    /// (their joint ranges widened by [`PathOptions::sample_margin_rad`]), the others the whole
    /// joint table.
    pub attempts: usize,
    /// RRT-Connect iterations per attempt.
    pub iterations: usize,
    /// Joint-space step of the trees (Euclidean norm over the 7 joints), radians.
    pub extend_rad: f64,
    /// Largest joint change between two poses checked along an edge, radians.
    pub check_step_rad: f64,
    /// Clearance kept beyond every requirement, metres: the preflight checks every tick of the
    /// time-parametrised path against the requirements themselves, so a path that keeps this
    /// buffer at its checked poses keeps the requirements between them.
    pub buffer_m: f64,
    /// Random shortcut tries on a found path.
    pub shortcut_rounds: usize,
    /// How far beyond the start's and goal's range each joint is sampled in the first attempts.
    pub sample_margin_rad: f64,
}

impl Default for PathOptions {
    fn default() -> Self {
        Self {
            seed: 27,
            attempts: 4,
            iterations: 3000,
            extend_rad: 0.1,
            check_step_rad: 0.01,
            buffer_m: 0.01,
            shortcut_rounds: 150,
            sample_margin_rad: 1.0,
        }
    }
}

/// The rule nearest to being broken at a pose: the obstacle in the way.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Nearest {
    /// What: `keep-out target`, `wall x+`, `camera-target distance`, `joint 4 limit`.
    pub obstacle: String,
    /// The arm's part nearest it: a capsule name, or `joint N`.
    pub part: String,
    /// The clearance there (metres; radians to the limit for a joint), and what the lab requires.
    pub clearance: f64,
    pub required: f64,
}

impl Nearest {
    /// How far beyond its requirement the pose is (negative: the rule is broken).
    pub fn excess(&self) -> f64 {
        self.clearance - self.required
    }
}

impl std::fmt::Display for Nearest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.obstacle.ends_with(" limit") {
            write!(
                f,
                "{} is {:.4} rad inside its {} (required {:.4} rad)",
                self.part, self.clearance, self.obstacle, self.required
            )
        } else {
            write!(
                f,
                "'{}' comes {:.4} m from the {} (clearance required {} m)",
                self.part, self.clearance, self.obstacle, self.required
            )
        }
    }
}

/// The lab's free space as the planner sees it: the preflight's clearances plus a buffer.
#[derive(Debug, Clone)]
pub struct FreeSpace {
    obstacles: Obstacles,
    /// The joint table less the lab's margin.
    lo: Joints,
    hi: Joints,
    wall_m: f64,
    keepout_m: f64,
    camera_target_m: f64,
    buffer_m: f64,
}

impl FreeSpace {
    pub fn new(lab: &LabConfig, buffer_m: f64) -> Self {
        let limits = lab.arm.joint_table.limits();
        let margin = lab.margins.joint_limit_rad;
        Self {
            obstacles: Obstacles::new(lab),
            lo: std::array::from_fn(|j| limits[j].0 + margin),
            hi: std::array::from_fn(|j| limits[j].1 - margin),
            wall_m: lab.margins.wall_m,
            keepout_m: lab.margins.keepout_m,
            camera_target_m: lab.camera.min_target_distance_m,
            buffer_m,
        }
    }

    /// The nearest rule at `q` (the one with the least excess over its requirement), among the
    /// joint limits, the walls, the keep-outs and the camera-target distance.
    pub fn nearest(&self, q: &Joints) -> Nearest {
        let pose = self.obstacles.at(q);
        let mut best: Option<Nearest> = None;
        let mut offer = |n: Nearest| {
            let e = n.excess();
            if best.as_ref().is_none_or(|b| e.is_nan() || e < b.excess()) {
                best = Some(n);
            }
        };
        for (j, v) in q.iter().enumerate() {
            let inside = (v - self.lo[j]).min(self.hi[j] - v);
            offer(Nearest {
                obstacle: "joint limit".into(),
                part: format!("joint {}", j + 1),
                clearance: inside,
                required: 0.0,
            });
        }
        for (f, (d, c)) in pose.faces.iter().enumerate() {
            offer(Nearest {
                obstacle: FACE_NAMES[f].into(),
                part: CAPSULE_NAMES[*c].into(),
                clearance: *d,
                required: self.wall_m,
            });
        }
        for (i, (d, c)) in pose.keepouts.iter().enumerate() {
            offer(Nearest {
                obstacle: format!("keep-out {}", self.obstacles.keepouts[i].0),
                part: CAPSULE_NAMES[*c].into(),
                clearance: *d,
                required: self.keepout_m,
            });
        }
        offer(Nearest {
            obstacle: "camera-target distance".into(),
            part: "camera".into(),
            clearance: pose.camera_target_m,
            required: self.camera_target_m,
        });
        best.unwrap_or_else(|| Nearest {
            obstacle: "nothing".into(),
            part: String::new(),
            clearance: f64::INFINITY,
            required: 0.0,
        })
    }

    /// True when every joint is inside its limits and every clearance keeps the buffer beyond
    /// its requirement (cheaper than [`FreeSpace::nearest`]: no names).
    pub fn is_free(&self, q: &Joints) -> bool {
        if (0..DOF).any(|j| !(q[j] >= self.lo[j] && q[j] <= self.hi[j])) {
            return false;
        }
        let pose = self.obstacles.at(q);
        let b = self.buffer_m;
        pose.faces.iter().all(|(d, _)| *d >= self.wall_m + b)
            && pose.keepouts.iter().all(|(d, _)| *d >= self.keepout_m + b)
            && pose.camera_target_m >= self.camera_target_m + b
    }

    /// The poses checked along the straight joint-space segment `a`-`b`: every
    /// `step` radians of the joint that moves most, both ends included.
    fn segment(a: &Joints, b: &Joints, step: f64) -> impl Iterator<Item = Joints> {
        let span = (0..DOF).map(|j| (b[j] - a[j]).abs()).fold(0.0, f64::max);
        let n = (span / step).ceil().max(1.0) as usize;
        let (a, b) = (*a, *b);
        (0..=n).map(move |i| {
            let s = i as f64 / n as f64;
            std::array::from_fn(|j| a[j] + (b[j] - a[j]) * s)
        })
    }

    /// True when every pose checked along `a`-`b` is free.
    pub fn segment_free(&self, a: &Joints, b: &Joints, step: f64) -> bool {
        Self::segment(a, b, step).all(|q| self.is_free(&q))
    }

    /// The worst pose along `a`-`b`: what the straight move runs into.
    pub fn worst_on_segment(&self, a: &Joints, b: &Joints, step: f64) -> Nearest {
        Self::segment(a, b, step)
            .map(|q| self.nearest(&q))
            .fold(None::<Nearest>, |w, n| match w {
                Some(w) if w.excess() <= n.excess() => Some(w),
                _ => Some(n),
            })
            .unwrap_or_else(|| self.nearest(a))
    }
}

/// A path found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FoundPath {
    /// Start, via points, goal: joined by straight lines in joint space.
    pub waypoints: Vec<Joints>,
    /// `direct` (the straight line was free) or `rrt-connect`.
    pub planner: &'static str,
    /// The seed of the attempt that found it (`rrt-connect` only).
    pub seed: Option<u64>,
    /// Attempts made (0 for `direct`).
    pub attempts: usize,
}

impl FoundPath {
    /// Joint-space length, radians: the sum of the legs' Euclidean norms over the 7 joints.
    pub fn length_rad(&self) -> f64 {
        path_length(&self.waypoints)
    }
}

/// Joint-space length of a polyline, radians.
pub fn path_length(waypoints: &[Joints]) -> f64 {
    waypoints
        .windows(2)
        .map(|w| (0..DOF).map(|j| (w[1][j] - w[0][j]).powi(2)).sum::<f64>().sqrt())
        .sum()
}

/// Why no path was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    #[error("the start pose itself is not clear: {0}")]
    StartBlocked(Nearest),
    #[error("the goal pose itself is not clear: {0}")]
    GoalBlocked(Nearest),
    #[error(
        "no collision-free path found in {attempts} attempt(s) of {iterations} RRT-Connect \
         iterations; the straight move runs into it: {blocker}"
    )]
    NotFound { attempts: usize, iterations: usize, blocker: Nearest },
}

impl PathError {
    /// The obstacle in the way.
    pub fn blocker(&self) -> &Nearest {
        match self {
            PathError::StartBlocked(n) | PathError::GoalBlocked(n) => n,
            PathError::NotFound { blocker, .. } => blocker,
        }
    }
}

/// A collision-free path from `start` to `goal` in `lab`: the straight line when it is free,
/// else RRT-Connect, checked edge by edge and shortcut. Deterministic.
pub fn find_path(
    start: &Joints,
    goal: &Joints,
    lab: &LabConfig,
    options: &PathOptions,
) -> Result<FoundPath, PathError> {
    let space = FreeSpace::new(lab, options.buffer_m);
    // Start and goal need only keep the requirements (a trajectory may pass closer than the
    // buffer); so do the poses within `END_ZONE_RAD` of them, the way out and in.
    let relaxed = FreeSpace::new(lab, 0.0);
    let step = options.check_step_rad;
    if !relaxed.is_free(start) {
        return Err(PathError::StartBlocked(relaxed.nearest(start)));
    }
    if !relaxed.is_free(goal) {
        return Err(PathError::GoalBlocked(relaxed.nearest(goal)));
    }
    let pose_free = |q: &Joints| {
        space.is_free(q)
            || (near(q, start, END_ZONE_RAD) || near(q, goal, END_ZONE_RAD)) && relaxed.is_free(q)
    };
    let edge_free = |a: &Joints, b: &Joints| FreeSpace::segment(a, b, step).all(|q| pose_free(&q));
    if edge_free(start, goal) {
        return Ok(direct(start, goal));
    }
    for attempt in 0..options.attempts {
        let seed = options.seed.wrapping_add(attempt as u64);
        let rng = RefCell::new(ChaCha8Rng::seed_from_u64(seed));
        let (lo, hi) = sample_box(&space, start, goal, attempt, options.sample_margin_rad);
        let sample = || {
            let mut rng = rng.borrow_mut();
            (0..DOF).map(|j| rng.gen_range(lo[j]..=hi[j])).collect::<Vec<f64>>()
        };
        let is_free = |q: &[f64]| pose_free(&std::array::from_fn(|j| q[j]));
        let Ok(raw) = rrt::dual_rrt_connect(
            start,
            goal,
            is_free,
            sample,
            options.extend_rad,
            options.iterations,
        ) else {
            continue;
        };
        let mut path: Vec<Joints> = raw.iter().map(|q| std::array::from_fn(|j| q[j])).collect();
        // The trees check their nodes only: every edge is checked at the fine step.
        if !path.windows(2).all(|w| edge_free(&w[0], &w[1])) {
            continue;
        }
        shortcut(&mut path, &edge_free, options.shortcut_rounds, &mut rng.borrow_mut());
        return Ok(FoundPath {
            waypoints: path,
            planner: "rrt-connect",
            seed: Some(seed),
            attempts: attempt + 1,
        });
    }
    Err(PathError::NotFound {
        attempts: options.attempts,
        iterations: options.iterations,
        blocker: relaxed.worst_on_segment(start, goal, step),
    })
}

/// Around the start and the goal, poses need only keep the requirements, not the buffer, this
/// far in every joint (radians): a trajectory may start closer to an obstacle than the buffer.
const END_ZONE_RAD: f64 = 0.2;

fn direct(start: &Joints, goal: &Joints) -> FoundPath {
    FoundPath { waypoints: vec![*start, *goal], planner: "direct", seed: None, attempts: 0 }
}

/// True when every joint of `a` is within `tol` of `b`'s.
fn near(a: &Joints, b: &Joints, tol: f64) -> bool {
    (0..DOF).all(|j| (a[j] - b[j]).abs() <= tol)
}

/// Where attempt `attempt` samples: near the start and goal first, then the whole table.
fn sample_box(
    space: &FreeSpace,
    start: &Joints,
    goal: &Joints,
    attempt: usize,
    margin: f64,
) -> (Joints, Joints) {
    if attempt >= 2 {
        return (space.lo, space.hi);
    }
    let lo = std::array::from_fn(|j| (start[j].min(goal[j]) - margin).max(space.lo[j]));
    let hi = std::array::from_fn(|j| (start[j].max(goal[j]) + margin).min(space.hi[j]));
    (lo, hi)
}

/// Shorten `path`: random shortcuts between two of its waypoints (seeded), then a greedy pass
/// from the start to the farthest waypoint each can see. Only edges `edge_free` accepts are made.
fn shortcut(
    path: &mut Vec<Joints>,
    edge_free: &dyn Fn(&Joints, &Joints) -> bool,
    rounds: usize,
    rng: &mut ChaCha8Rng,
) {
    for _ in 0..rounds {
        if path.len() < 3 {
            break;
        }
        let i = rng.gen_range(0..path.len() - 2);
        let k = rng.gen_range(i + 2..path.len());
        if edge_free(&path[i], &path[k]) {
            path.drain(i + 1..k);
        }
    }
    let mut out = vec![path[0]];
    let mut i = 0;
    while i + 1 < path.len() {
        let far = (i + 1..path.len()).rev().find(|&k| k == i + 1 || edge_free(&path[i], &path[k]));
        let k = far.unwrap_or(i + 1);
        out.push(path[k]);
        i = k;
    }
    *path = out;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lab::DEFAULT_REST_Q;

    /// The station-keeping preset's pose in the default lab (`hitl plan --preset
    /// station-keeping`): the camera close in front of the target, its body under the target.
    const STATION: Joints = [-1.319, 0.533, 0.929, 1.177, 0.963, 1.658, -0.661];

    #[test]
    fn the_rest_pose_is_free_and_the_straight_move_to_station_keeping_is_not() {
        let lab = LabConfig::default();
        let space = FreeSpace::new(&lab, 0.01);
        assert!(space.is_free(&DEFAULT_REST_Q), "{}", space.nearest(&DEFAULT_REST_Q));
        assert!(space.nearest(&STATION).excess() >= 0.0, "{}", space.nearest(&STATION));
        let worst = space.worst_on_segment(&DEFAULT_REST_Q, &STATION, 0.01);
        assert!(worst.excess() < 0.0, "{worst}");
    }

    #[test]
    fn a_path_around_the_target_is_found_deterministically_and_every_edge_is_clear() {
        let lab = LabConfig::default();
        let options = PathOptions::default();
        let t0 = std::time::Instant::now();
        let path = find_path(&DEFAULT_REST_Q, &STATION, &lab, &options).expect("path");
        let took = t0.elapsed();
        assert_eq!(path.planner, "rrt-connect");
        assert_eq!(path.waypoints[0], DEFAULT_REST_Q);
        assert_eq!(*path.waypoints.last().expect("goal"), STATION);
        let relaxed = FreeSpace::new(&lab, 0.0);
        for w in path.waypoints.windows(2) {
            assert!(relaxed.segment_free(&w[0], &w[1], 0.005));
        }
        let again = find_path(&DEFAULT_REST_Q, &STATION, &lab, &options).expect("path");
        assert_eq!(again, path);
        eprintln!(
            "{} waypoints, {:.2} rad, attempt {}, {:?}",
            path.waypoints.len(),
            path.length_rad(),
            path.attempts,
            took
        );
    }

    #[test]
    fn a_free_straight_line_is_taken_as_is() {
        let lab = LabConfig::default();
        let mut goal = DEFAULT_REST_Q;
        goal[0] += 0.3;
        let path = find_path(&DEFAULT_REST_Q, &goal, &lab, &PathOptions::default()).expect("path");
        assert_eq!((path.planner, path.waypoints.len()), ("direct", 2));
    }

    #[test]
    fn a_start_inside_a_keep_out_is_refused_naming_it() {
        let lab = LabConfig::default();
        // The hand reaching forward into the target (docs/preflight.md).
        let start = [0.0, 0.3, 0.0, 1.2, 0.0, 0.9, 0.0];
        let e =
            find_path(&start, &DEFAULT_REST_Q, &lab, &PathOptions::default()).expect_err("refused");
        assert!(matches!(e, PathError::StartBlocked(_)), "{e}");
        assert!(e.blocker().obstacle.starts_with("keep-out"), "{e}");
    }
}
