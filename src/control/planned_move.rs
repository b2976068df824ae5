//! The moves `hitl` plans between two rests before anything moves: the approach from the arm's
//! pose to a trajectory's first setpoint, the retreat from its last to the lab's rest pose, and
//! `hitl park`.
//!
//! [`plan_safe_move`]: a collision-free path (`hitl_trajectories::path`: the straight joint-space
//! line when it keeps every clearance, else RRT-Connect around the target, its tripod, the light
//! and the walls), time-parametrised as rest-to-rest Ruckig legs along it within the lab's
//! approach limits (`limits.approach_*`), and the whole move, tick by tick, through the
//! preflight's rules (`preflight::check_move`). A move that cannot be made is refused naming the
//! obstacle in the way. Deterministic (the planner is seeded): the same start, goal and lab give
//! the same setpoints.

use super::motion::{plan_path, MotionError, MoveLimits};
use hitl_hal::JointState;
use hitl_hal::Joints;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::path::{self, FoundPath, PathError, PathOptions};
use hitl_trajectories::preflight::{self, Clearance, MoveProfile, PreflightReport, Rule};
use std::collections::BTreeMap;
use std::time::Instant;

/// A move planned and checked: what the loop plays, and how it was found.
#[derive(Debug, Clone)]
pub struct PlannedMove {
    /// `approach` or `retreat`.
    pub name: &'static str,
    /// One setpoint per tick after the start, the last at rest on the goal (empty when the arm
    /// is already there).
    pub setpoints: Vec<JointState>,
    /// The path: start, via points, goal.
    pub path: FoundPath,
    /// The preflight of every tick of the move.
    pub report: PreflightReport,
    /// Wall time the path search and the checks took, seconds.
    pub planning_s: f64,
}

/// Why a move cannot be made (exit 3): the message names the obstacle in the way.
#[derive(Debug, Clone, thiserror::Error)]
pub enum MoveRefused {
    #[error("{0}")]
    NoPath(PathError),
    #[error("the planned path breaks the preflight's rules:\n{0}")]
    Unsafe(String),
    #[error("Ruckig could not time the path: {0}")]
    Motion(MotionError),
}

impl PlannedMove {
    /// Duration from the start to the goal, seconds.
    pub fn duration_s(&self) -> f64 {
        self.setpoints.len() as f64 / self.report.rate_hz
    }

    /// The clearance nearest its requirement over the whole move (`None` for an empty move).
    pub fn nearest(&self) -> Option<&Clearance> {
        self.report
            .clearances
            .iter()
            .min_by(|a, b| (a.min_m - a.required_m).total_cmp(&(b.min_m - b.required_m)))
    }

    /// One line for people: planner, length, duration, nearest obstacle, planning time.
    pub fn describe(&self) -> String {
        if self.setpoints.is_empty() {
            return format!("{}: none (the arm is already there)", self.name);
        }
        let how = match self.path.planner {
            "direct" => "straight in joint space".to_string(),
            p => format!(
                "{p} around the obstacles ({} waypoints, seed {})",
                self.path.waypoints.len(),
                self.path.seed.unwrap_or_default()
            ),
        };
        let nearest = self
            .nearest()
            .map(|c| {
                format!(
                    ", nearest obstacle {} at {:.3} m ('{}', required {} m)",
                    c.surface, c.min_m, c.capsule, c.required_m
                )
            })
            .unwrap_or_default();
        format!(
            "{}: {how}, {:.2} rad, {:.2} s{nearest}; planned in {:.3} s",
            self.name,
            self.path.length_rad(),
            self.duration_s(),
            self.planning_s
        )
    }

    /// The plan as JSON (`hitl check --json`, the recording's metadata).
    pub fn to_json(&self) -> serde_json::Value {
        let nearest = self.nearest().map(|c| {
            serde_json::json!({
                "surface": c.surface, "capsule": c.capsule, "min_m": c.min_m,
                "required_m": c.required_m, "time_s": c.time_s,
            })
        });
        serde_json::json!({
            "move": self.name,
            "planner": self.path.planner,
            "seed": self.path.seed,
            "attempts": self.path.attempts,
            "waypoints": self.path.waypoints,
            "length_rad": self.path.length_rad(),
            "duration_s": self.duration_s(),
            "ticks": self.setpoints.len(),
            "rate_hz": self.report.rate_hz,
            "nearest": nearest,
            "planning_s": self.planning_s,
        })
    }

    /// The plan as an MCAP metadata record's string map.
    pub fn metadata(&self) -> BTreeMap<String, String> {
        match self.to_json() {
            serde_json::Value::Object(o) => o
                .into_iter()
                .map(|(k, v)| match v {
                    serde_json::Value::String(s) => (k, s),
                    v => (k, v.to_string()),
                })
                .collect(),
            _ => BTreeMap::new(),
        }
    }
}

/// The lab's approach limits (`limits.approach_*`), which every planned move keeps.
pub fn approach_limits(lab: &LabConfig) -> MoveLimits {
    let l = &lab.limits;
    MoveLimits::uniform(
        l.approach_velocity_rad_s,
        l.approach_acceleration_rad_s2,
        l.approach_jerk_rad_s3,
    )
}

/// Plan the move `name` from rest at `from` to rest at `to` in `lab` at `rate_hz`: a collision-free
/// path, timed within the approach limits, every tick through the preflight.
pub fn plan_safe_move(
    name: &'static str,
    from: &Joints,
    to: &Joints,
    lab: &LabConfig,
    rate_hz: f64,
) -> Result<PlannedMove, MoveRefused> {
    let t0 = Instant::now();
    let path =
        path::find_path(from, to, lab, &PathOptions::default()).map_err(MoveRefused::NoPath)?;
    let limits = approach_limits(lab);
    // A lab whose TCP speed limit the approach limits would break (a slow lab) gets the move
    // slowed down until it passes: velocity by the ratio, acceleration and jerk by its square and
    // cube (a few tries, each confirmed by the full check). Still refused after them: the
    // first try's violations (at the lab's own limits) say why, without asking again.
    let mut scale = 1.0;
    let mut first_refusal = None;
    for _ in 0..4 {
        let scaled = MoveLimits {
            velocity: limits.velocity.map(|v| v * scale),
            acceleration: limits.acceleration.map(|a| a * scale * scale),
            jerk: limits.jerk.map(|j| j * scale * scale * scale),
        };
        let (setpoints, report) = time_and_check(name, from, &path, &scaled, lab, rate_hz)?;
        if report.is_safe() {
            return Ok(PlannedMove {
                name,
                setpoints,
                path,
                report,
                planning_s: t0.elapsed().as_secs_f64(),
            });
        }
        let only_tcp = report.violations.iter().all(|v| v.rule == Rule::TcpSpeed);
        let tcp = &report.tcp_speed;
        // NaN or no speed at all: nothing slowing down can cure.
        if !only_tcp || tcp.peak_m_s.is_nan() || tcp.peak_m_s <= 0.0 {
            return Err(MoveRefused::Unsafe(violation_lines(&report)));
        }
        scale *= 0.95 * tcp.limit_m_s / tcp.peak_m_s;
        first_refusal.get_or_insert_with(|| violation_lines(&report));
    }
    Err(MoveRefused::Unsafe(first_refusal.unwrap_or_default()))
}

fn violation_lines(report: &PreflightReport) -> String {
    let lines: Vec<String> =
        report.violations.iter().map(|v| format!("  - {}", v.message)).collect();
    lines.join("\n")
}

/// Time `path` as straight rest-to-rest legs within `limits` and run the preflight over every
/// tick of it.
fn time_and_check(
    name: &str,
    from: &Joints,
    path: &FoundPath,
    limits: &MoveLimits,
    lab: &LabConfig,
    rate_hz: f64,
) -> Result<(Vec<JointState>, PreflightReport), MoveRefused> {
    let dt = 1.0 / rate_hz;
    let (setpoints, ends) = plan_path(&path.waypoints, limits, dt).map_err(MoveRefused::Motion)?;
    let mut profile = MoveProfile {
        name: name.to_string(),
        rate_hz,
        q: Vec::with_capacity(setpoints.len() + 1),
        qd: Vec::with_capacity(setpoints.len() + 1),
        qdd: Vec::with_capacity(setpoints.len() + 1),
        via_ticks: ends,
    };
    profile.q.push(*from);
    profile.qd.push([0.0; hitl_hal::DOF]);
    profile.qdd.push([0.0; hitl_hal::DOF]);
    for s in &setpoints {
        profile.q.push(s.q);
        profile.qd.push(s.qd);
        profile.qdd.push(s.qdd);
    }
    let report = preflight::check_move(&profile, lab);
    Ok((setpoints, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_trajectories::lab::DEFAULT_REST_Q;

    /// The station-keeping preset's pose in the default lab.
    const STATION: Joints = [-1.319, 0.533, 0.929, 1.177, 0.963, 1.658, -0.661];

    #[test]
    fn the_approach_to_station_keeping_goes_around_the_target_and_keeps_every_clearance() {
        let lab = LabConfig::default();
        let m = plan_safe_move("approach", &DEFAULT_REST_Q, &STATION, &lab, 250.0).expect("plan");
        assert_eq!(m.path.planner, "rrt-connect");
        assert!(m.report.is_safe());
        assert_eq!(m.setpoints.last().expect("setpoints").q, STATION);
        for c in &m.report.clearances {
            assert!(c.min_m >= c.required_m, "{c:?}");
        }
        let again = plan_safe_move("approach", &DEFAULT_REST_Q, &STATION, &lab, 250.0).expect("");
        assert_eq!(again.setpoints, m.setpoints);
        assert!(m.describe().contains("nearest obstacle"), "{}", m.describe());
        // The retreat from there is planned the same way.
        let back = plan_safe_move("retreat", &STATION, &DEFAULT_REST_Q, &lab, 250.0).expect("");
        assert_eq!(back.setpoints.last().expect("setpoints").q, DEFAULT_REST_Q);
    }

    #[test]
    fn a_lab_with_a_slow_tcp_limit_gets_a_slower_move() {
        let mut lab = LabConfig::default();
        lab.limits.tcp_speed_m_s = 0.02;
        let mut goal = DEFAULT_REST_Q;
        goal[1] += 0.1;
        let m = plan_safe_move("approach", &DEFAULT_REST_Q, &goal, &lab, 250.0).expect("plan");
        assert!(m.report.tcp_speed.peak_m_s <= 0.02, "{:?}", m.report.tcp_speed);
        let fast = plan_safe_move("approach", &DEFAULT_REST_Q, &goal, &LabConfig::default(), 250.0)
            .expect("plan");
        assert!(m.duration_s() > 2.0 * fast.duration_s());
    }

    #[test]
    fn a_start_inside_a_keep_out_is_refused_naming_it() {
        let lab = LabConfig::default();
        let boxed = [0.0, 0.3, 0.0, 1.2, 0.0, 0.9, 0.0];
        let e = plan_safe_move("approach", &boxed, &STATION, &lab, 250.0).expect_err("refused");
        assert!(e.to_string().contains("keep-out"), "{e}");
    }
}
