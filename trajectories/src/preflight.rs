//! The preflight: the rules `hitl check` applies and `hitl run` applies again before anything
//! moves. Checked at every setpoint tick of the [`SetpointTable`] (what the arm will actually be
//! sent, spline swings between waypoints included):
//!
//! - joint positions inside the lab's xArm7 joint-limit table (`arm.joint_table`, named in the
//!   message) shrunk by `margins.joint_limit_rad`;
//! - peak |velocity|, |acceleration|, |jerk| per joint against `limits`;
//! - per-tick step (largest joint change between two setpoints) against `limits.max_step_rad`
//!   (servo mode runs each step at full speed);
//! - peak linear speed of the TCP (flange origin and camera optical centre, forward kinematics
//!   differenced between setpoints) against `limits.tcp_speed_m_s` (the box's servo_j error 60);
//! - clearance of every arm capsule (links, flange, camera body) to each enclosure face (x-, x+,
//!   y-, y+, floor, ceiling), keeping `margins.wall_m`, and to each keep-out (target, tripod,
//!   light), keeping `margins.keepout_m`;
//! - camera optical centre to target centre at least `camera.min_target_distance_m`.
//!
//! Exemption: the `base` capsule stands on the floor, so its floor clearance is not checked (it
//! is bolted there; its hemispherical end reaches below the base plate by construction). Every
//! other capsule is checked against every surface, and the base capsule against the walls,
//! ceiling and keep-outs (a lab config that puts the base too near a wall is refused too).
//! Each rule is its own function over the setpoint profile (`Ticks`): `joint_limit_rule`,
//! `joint_derivative_rule`, `tcp_speed_rule` and `clearance_rule`; `check_ticks` runs them in
//! that order (one forward-kinematics pass feeds the last two). A run asks each question once:
//! [`check`] over the file's setpoint table, [`check_move`] over each planned move (the approach,
//! the retreat), and [`check_joint_limits`] alone when the connected arm's joint table is tighter
//! than the lab's (the only rule a table changes).
//!
//! See `docs/preflight.md`.

use crate::geometry::Capsule;
use crate::kinematics::{self, Joints, CAPSULE_NAMES, DOF};
use crate::lab::LabConfig;
use crate::timing::SetpointTable;
use crate::trajectory::Trajectory;
use nalgebra::Point3;
use serde::Serialize;

/// Names of the enclosure faces, in [`Capsule::box_clearances`] order.
pub const FACE_NAMES: [&str; 6] = ["wall x-", "wall x+", "wall y-", "wall y+", "floor", "ceiling"];

/// Index of the base capsule in [`kinematics::arm_capsules`].
const BASE: usize = 0;
/// Index of the floor in [`FACE_NAMES`].
const FLOOR: usize = 4;

/// Peaks of one joint over the whole table, against its limits.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointPeaks {
    /// 1-based joint number, as the lab says it.
    pub joint: usize,
    /// Lowest and highest setpoint, radians.
    pub min_rad: f64,
    pub max_rad: f64,
    /// Allowed range: the xArm7 limits shrunk by the margin, radians.
    pub allowed_min_rad: f64,
    pub allowed_max_rad: f64,
    pub peak_velocity: f64,
    pub velocity_limit: f64,
    pub peak_acceleration: f64,
    pub acceleration_limit: f64,
    pub peak_jerk: f64,
    pub jerk_limit: f64,
    /// Largest change between two setpoints, radians.
    pub peak_step_rad: f64,
    pub step_limit_rad: f64,
}

/// The smallest clearance to one surface over the whole table, and where it happened.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Clearance {
    /// The surface: a face of [`FACE_NAMES`], `keep-out target|tripod|light`, or
    /// `camera-target distance`.
    pub surface: String,
    /// Smallest clearance, metres (negative: overlapping). For `camera-target distance`, the
    /// smallest distance from the optical centre to the target centre.
    pub min_m: f64,
    /// What the lab requires (the margin, or the minimum distance), metres.
    pub required_m: f64,
    pub tick: usize,
    pub time_s: f64,
    /// The capsule closest to the surface (`camera` for the camera-target distance).
    pub capsule: String,
}

/// The peak linear speed of the TCP over the whole table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TcpSpeed {
    /// Peak speed, m/s (of the faster point, see `point`).
    pub peak_m_s: f64,
    /// Which point reached it: `flange` or `camera` (the optical centre).
    pub point: String,
    pub tick: usize,
    pub time_s: f64,
    /// `limits.tcp_speed_m_s`.
    pub limit_m_s: f64,
}

/// The captures' fastest rate against what the camera can follow.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CaptureRate {
    /// Fastest capture rate, Hz: the inverse of the shortest gap between two captures.
    pub peak_hz: f64,
    /// The later capture of that gap: its tick and time.
    pub tick: usize,
    pub time_s: f64,
    /// The fastest rate the camera follows, Hz.
    pub limit_hz: f64,
    /// The camera and why that is its limit, in words.
    pub camera: String,
}

/// What a violation is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    JointLimit,
    Velocity,
    Acceleration,
    Jerk,
    Step,
    TcpSpeed,
    Wall,
    KeepOut,
    CameraTargetDistance,
    /// Captures faster than the camera can follow ([`check_capture_rate`]).
    CaptureRate,
}

/// One broken rule, with where it is worst.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Violation {
    pub rule: Rule,
    /// One line naming what and where, for people.
    pub message: String,
    /// Where the rule is broken worst.
    pub tick: usize,
    pub time_s: f64,
    /// The waypoint segment that tick lies in (the waypoint at or before it).
    pub waypoint: usize,
    /// 1-based joint, for joint rules.
    pub joint: Option<usize>,
    /// Surface and capsule, for clearance rules.
    pub surface: Option<String>,
    pub capsule: Option<String>,
}

/// Everything `hitl check` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PreflightReport {
    pub safe: bool,
    pub waypoints: usize,
    pub duration_s: f64,
    pub ticks: usize,
    /// Ticks of the lead-in (from rest into a file that starts moving) and of the lead-out (to
    /// rest from a file that ends moving), both included in `ticks` and `duration_s`.
    pub lead_in_ticks: usize,
    pub lead_out_ticks: usize,
    pub rate_hz: f64,
    pub speed_scale: f64,
    pub captures: usize,
    /// The xArm7 joint-limit table the joint positions were checked against.
    pub joint_table: String,
    pub joints: Vec<JointPeaks>,
    pub clearances: Vec<Clearance>,
    pub tcp_speed: TcpSpeed,
    /// The captures' fastest rate against the camera's limit, when a camera was named
    /// ([`check_capture_rate`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capture_rate: Option<CaptureRate>,
    pub violations: Vec<Violation>,
    /// Things worth knowing that are not unsafe (e.g. two captures falling on one tick).
    pub warnings: Vec<String>,
}

impl PreflightReport {
    /// True when no rule is broken.
    pub fn is_safe(&self) -> bool {
        self.violations.is_empty()
    }
}

/// The running minimum of one clearance.
#[derive(Clone, Copy)]
struct MinTrack {
    value: f64,
    tick: usize,
    capsule: usize,
}

impl MinTrack {
    const NONE: MinTrack = MinTrack { value: f64::INFINITY, tick: 0, capsule: 0 };

    fn offer(&mut self, value: f64, tick: usize, capsule: usize) {
        // A NaN is taken and then kept, so it can never hide.
        if value.is_nan() || value < self.value {
            *self = MinTrack { value, tick, capsule };
        }
    }
}

/// Where a setpoint table's ticks lie, for the rules' messages: the waypoint segment of a tick,
/// and in words near which waypoint or in which ramp.
struct TablePlaces<'a> {
    waypoint_ticks: &'a [usize],
    file: std::ops::Range<usize>,
    /// Waypoints in the file.
    waypoints: usize,
}

impl<'a> TablePlaces<'a> {
    fn new(table: &'a SetpointTable, waypoints: usize) -> Self {
        Self { waypoint_ticks: &table.waypoint_ticks, file: table.file_ticks(), waypoints }
    }

    fn waypoint_of(&self, tick: usize) -> usize {
        self.waypoint_ticks.partition_point(|w| *w <= tick).saturating_sub(1)
    }

    fn place(&self, tick: usize) -> String {
        if tick < self.file.start {
            "in the lead-in, before waypoint 0".to_string()
        } else if tick >= self.file.end {
            format!("in the lead-out, after waypoint {}", self.waypoints.saturating_sub(1))
        } else {
            format!("near waypoint {}", self.waypoint_of(tick))
        }
    }
}

/// A setpoint table's ticks as the rules read them.
fn table_ticks(table: &SetpointTable) -> Ticks<'_> {
    Ticks {
        rate_hz: table.rate_hz,
        dt: table.dt,
        q: &table.q,
        qd: &table.qd,
        qdd: &table.qdd,
        jerk: &table.jerk,
    }
}

/// Run every preflight rule over `table` (built from `traj`) in `lab`.
pub fn check(traj: &Trajectory, table: &SetpointTable, lab: &LabConfig) -> PreflightReport {
    let places = TablePlaces::new(table, traj.len());
    let ticks = table_ticks(table);
    let rules = check_ticks(&ticks, lab, &|k| places.waypoint_of(k), &|k| places.place(k));
    let mut warnings = Vec::new();
    let shared = table.captures.windows(2).filter(|w| w[0].tick == w[1].tick).count();
    if shared > 0 {
        warnings.push(format!(
            "{shared} capture waypoint(s) fall on the same tick as the previous capture at {} Hz; \
             they fire once",
            table.rate_hz
        ));
    }
    PreflightReport {
        safe: rules.violations.is_empty(),
        waypoints: traj.len(),
        duration_s: table.duration_s,
        ticks: table.ticks(),
        lead_in_ticks: table.lead_in_ticks,
        lead_out_ticks: table.lead_out_ticks,
        rate_hz: table.rate_hz,
        speed_scale: table.speed_scale,
        captures: traj.capture_count(),
        joint_table: lab.arm.joint_table.name().to_string(),
        joints: rules.joints,
        clearances: rules.clearances,
        tcp_speed: rules.tcp_speed,
        capture_rate: None,
        violations: rules.violations,
        warnings,
    }
}

/// Only the joint-limit rule over `table` (built from a file of `waypoints` waypoints) in `lab`:
/// the one question a different joint table asks again (the connected arm's, when it is tighter
/// than the lab's; every other rule's answer does not depend on the table). The violations are
/// those [`check`] would give for joint limits, worded the same.
pub fn check_joint_limits(
    table: &SetpointTable,
    waypoints: usize,
    lab: &LabConfig,
) -> Vec<Violation> {
    let places = TablePlaces::new(table, waypoints);
    let ticks = table_ticks(table);
    let waypoint_of = |k| places.waypoint_of(k);
    let place = |k| places.place(k);
    let at = Locator { ticks: &ticks, waypoint_of: &waypoint_of, place: &place };
    let mut violations = Vec::new();
    for j in 0..DOF {
        joint_limit_rule(&ticks, lab, j, &at, &mut violations);
    }
    violations
}

/// A planned move between two rests (the approach to a trajectory's first setpoint, the retreat
/// to the lab's rest pose) as the setpoints the loop will send, for [`check_move`]: tick 0 is
/// the pose the arm starts from, at rest; one setpoint per tick after it, the last at rest on the
/// goal.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MoveProfile {
    /// What the move is, for messages: `approach`, `retreat`.
    pub name: String,
    /// Control rate, Hz.
    pub rate_hz: f64,
    /// Joint positions, velocities and accelerations per tick.
    pub q: Vec<Joints>,
    pub qd: Vec<Joints>,
    pub qdd: Vec<Joints>,
    /// The ticks at which the move reaches each waypoint of its path (the last: the goal).
    pub via_ticks: Vec<usize>,
}

impl MoveProfile {
    /// Number of ticks, the start included.
    pub fn ticks(&self) -> usize {
        self.q.len()
    }

    /// Duration from the start to the goal, seconds.
    pub fn duration_s(&self) -> f64 {
        self.ticks().saturating_sub(1) as f64 / self.rate_hz
    }
}

/// Run every preflight rule over a planned move (as the loop will send it) in `lab`: the same
/// rules as [`check`], at every tick, jerk being the backward difference of acceleration (so the
/// junctions between the move's legs are checked too). The report's `waypoints` are the move's
/// path waypoints; it has no captures.
pub fn check_move(profile: &MoveProfile, lab: &LabConfig) -> PreflightReport {
    let dt = 1.0 / profile.rate_hz;
    let jerk: Vec<Joints> = (0..profile.qdd.len())
        .map(|k| {
            let prev = profile.qdd[k.saturating_sub(1)];
            std::array::from_fn(|j| (profile.qdd[k][j] - prev[j]) / dt)
        })
        .collect();
    let ticks = Ticks {
        rate_hz: profile.rate_hz,
        dt,
        q: &profile.q,
        qd: &profile.qd,
        qdd: &profile.qdd,
        jerk: &jerk,
    };
    let legs = profile.via_ticks.len();
    let waypoint_of = |tick: usize| profile.via_ticks.partition_point(|w| *w < tick);
    let place = |tick: usize| {
        if legs > 1 {
            format!("in the {}, leg {} of {legs}", profile.name, (waypoint_of(tick) + 1).min(legs))
        } else {
            format!("in the {}", profile.name)
        }
    };
    let rules = check_ticks(&ticks, lab, &waypoint_of, &place);
    PreflightReport {
        safe: rules.violations.is_empty(),
        waypoints: legs,
        duration_s: profile.duration_s(),
        ticks: profile.ticks(),
        lead_in_ticks: 0,
        lead_out_ticks: 0,
        rate_hz: profile.rate_hz,
        speed_scale: 1.0,
        captures: 0,
        joint_table: lab.arm.joint_table.name().to_string(),
        joints: rules.joints,
        clearances: rules.clearances,
        tcp_speed: rules.tcp_speed,
        capture_rate: None,
        violations: rules.violations,
        warnings: Vec::new(),
    }
}

/// The lab's obstacles as the preflight checks them: the arm's capsules against the enclosure's
/// faces (in the lab frame) and the keep-outs (in the base frame), and the camera's optical
/// centre against the target centre. One pose at a time ([`Obstacles::at`]); the preflight
/// offers every tick's, the path planner asks about the poses it tries.
#[derive(Debug, Clone)]
pub struct Obstacles {
    mount: hitl_hal::Pose,
    body: crate::kinematics::CameraBody,
    base_in_lab: hitl_hal::Pose,
    lo: Point3<f64>,
    hi: Point3<f64>,
    /// The keep-outs by name, in the base frame ([`LabConfig::keepouts_base`]).
    pub keepouts: [(&'static str, Capsule); 3],
    target: Point3<f64>,
}

/// The arm's clearances at one pose: each the smallest over the capsules, with the capsule's
/// index in [`CAPSULE_NAMES`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseClearances {
    /// Per enclosure face, in [`FACE_NAMES`] order (the base capsule not against the floor).
    pub faces: [(f64, usize); 6],
    /// Per keep-out, in [`Obstacles::keepouts`] order.
    pub keepouts: [(f64, usize); 3],
    /// Camera optical centre to target centre, metres.
    pub camera_target_m: f64,
    /// Flange origin and camera optical centre, base frame.
    pub points: [Point3<f64>; 2],
}

impl Obstacles {
    pub fn new(lab: &LabConfig) -> Self {
        let (lo, hi) = lab.enclosure_box();
        Self {
            mount: lab.camera_mount(),
            body: lab.camera.body,
            base_in_lab: lab.base_in_lab(),
            lo,
            hi,
            keepouts: lab.keepouts_base(),
            target: lab.target_position_base(),
        }
    }

    /// Every clearance the preflight checks, at `q`.
    pub fn at(&self, q: &Joints) -> PoseClearances {
        let flange = kinematics::flange_pose(q);
        let points = [
            Point3::from(flange.translation.vector),
            Point3::from((flange * self.mount).translation.vector),
        ];
        let mut faces = [MinTrack::NONE; 6];
        let mut keep = [MinTrack::NONE; 3];
        let capsules = kinematics::arm_capsules(q, &self.mount, &self.body);
        for (c, cap) in capsules.iter().enumerate() {
            let in_lab: Capsule = cap.transformed(&self.base_in_lab);
            for (f, d) in in_lab.box_clearances(&self.lo, &self.hi).iter().enumerate() {
                if !(c == BASE && f == FLOOR) {
                    faces[f].offer(*d, 0, c);
                }
            }
            for (i, (_, ko)) in self.keepouts.iter().enumerate() {
                keep[i].offer(cap.distance_to(ko), 0, c);
            }
        }
        PoseClearances {
            faces: faces.map(|t| (t.value, t.capsule)),
            keepouts: keep.map(|t| (t.value, t.capsule)),
            camera_target_m: (points[1] - self.target).norm(),
            points,
        }
    }
}

/// The setpoints the rules run over: entry `k` of each slice is tick `k`, at `k * dt` seconds.
struct Ticks<'a> {
    rate_hz: f64,
    dt: f64,
    q: &'a [Joints],
    qd: &'a [Joints],
    qdd: &'a [Joints],
    jerk: &'a [Joints],
}

impl Ticks<'_> {
    fn time_of(&self, tick: usize) -> f64 {
        tick as f64 * self.dt
    }
}

/// What the rules found over a run of ticks.
struct RuleResults {
    joints: Vec<JointPeaks>,
    clearances: Vec<Clearance>,
    tcp_speed: TcpSpeed,
    violations: Vec<Violation>,
}

/// Where a tick lies, for the rules' messages: its time, its waypoint segment and, in words,
/// its place in the table.
struct Locator<'a> {
    ticks: &'a Ticks<'a>,
    waypoint_of: &'a dyn Fn(usize) -> usize,
    place: &'a dyn Fn(usize) -> String,
}

impl Locator<'_> {
    /// A violation of `rule` worst at `tick`; `joint`, `surface`, `capsule` say what broke it.
    fn violation(
        &self,
        rule: Rule,
        message: String,
        tick: usize,
        joint: Option<usize>,
        surface: Option<String>,
        capsule: Option<String>,
    ) -> Violation {
        Violation {
            rule,
            message,
            tick,
            time_s: self.ticks.time_of(tick),
            waypoint: (self.waypoint_of)(tick),
            joint,
            surface,
            capsule,
        }
    }
}

/// Every rule over `table`'s ticks: `waypoint_of` says which waypoint segment a tick lies in,
/// `place` where it is, in words. Violations come joint by joint (limit, then derivatives),
/// then TCP speed, then clearances.
fn check_ticks(
    table: &Ticks<'_>,
    lab: &LabConfig,
    waypoint_of: &dyn Fn(usize) -> usize,
    place: &dyn Fn(usize) -> String,
) -> RuleResults {
    let at = Locator { ticks: table, waypoint_of, place };
    let mut violations = Vec::new();
    let joints = (0..DOF)
        .map(|j| {
            let range = joint_limit_rule(table, lab, j, &at, &mut violations);
            joint_derivative_rule(table, lab, j, range, &at, &mut violations)
        })
        .collect();
    // One forward-kinematics pass feeds both pose rules.
    let obstacles = Obstacles::new(lab);
    let mut tcp = TcpTrack::default();
    let mut nearest = NearestTrack::default();
    for (k, q) in table.q.iter().enumerate() {
        let pose = obstacles.at(q);
        tcp.offer(k, &pose, table.rate_hz);
        nearest.offer(k, &pose);
    }
    let tcp_speed = tcp_speed_rule(&tcp, lab, &at, &mut violations);
    let clearances = clearance_rule(&nearest, &obstacles, lab, &at, &mut violations);
    RuleResults { joints, clearances, tcp_speed, violations }
}

/// Joint `j`'s lowest and highest setpoint against its allowed range.
struct JointRange {
    min_rad: f64,
    max_rad: f64,
    allowed_min_rad: f64,
    allowed_max_rad: f64,
}

/// Rule: joint `j` stays inside the lab's joint-limit table shrunk by the margin.
fn joint_limit_rule(
    table: &Ticks<'_>,
    lab: &LabConfig,
    j: usize,
    at: &Locator<'_>,
    violations: &mut Vec<Violation>,
) -> JointRange {
    let margin = lab.margins.joint_limit_rad;
    let joint_table = lab.arm.joint_table;
    let limits = joint_table.limits()[j];
    let (lo, hi) = (limits.0 + margin, limits.1 - margin);
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut worst_out = (0.0f64, 0usize);
    for (k, q) in table.q.iter().enumerate() {
        let v = q[j];
        min = if v < min { v } else { min };
        max = if v > max { v } else { max };
        let out = if v.is_nan() { f64::INFINITY } else { (lo - v).max(v - hi) };
        if out > worst_out.0 {
            worst_out = (out, k);
        }
    }
    if worst_out.0 > 0.0 {
        let k = worst_out.1;
        let joint = j + 1;
        let message = format!(
            "joint {joint} reaches {:.4} rad at tick {k} ({:.3} s, {}): outside its allowed \
             range [{lo:.4}, {hi:.4}] rad (joint table {joint_table} less a {margin} rad margin)",
            table.q[k][j],
            table.time_of(k),
            (at.place)(k)
        );
        violations.push(at.violation(Rule::JointLimit, message, k, Some(joint), None, None));
    }
    JointRange { min_rad: min, max_rad: max, allowed_min_rad: lo, allowed_max_rad: hi }
}

/// The largest |x[k][j]| over the ticks and where (a NaN is taken and kept).
fn peak_of(x: &[Joints], j: usize) -> (f64, usize) {
    x.iter().enumerate().fold((0.0f64, 0usize), |(m, at), (k, v)| {
        if v[j].is_nan() || v[j].abs() > m {
            (v[j].abs(), k)
        } else {
            (m, at)
        }
    })
}

/// The largest change of joint `j` between two setpoints and where (the later tick).
fn peak_step(q: &[Joints], j: usize) -> (f64, usize) {
    let mut step = (0.0f64, 0usize);
    for k in 1..q.len() {
        let s = (q[k][j] - q[k - 1][j]).abs();
        if s.is_nan() || s > step.0 {
            step = (s, k);
        }
    }
    step
}

/// Rule: joint `j`'s peak velocity, acceleration, jerk and per-tick step stay within `limits`.
fn joint_derivative_rule(
    table: &Ticks<'_>,
    lab: &LabConfig,
    j: usize,
    range: JointRange,
    at: &Locator<'_>,
    violations: &mut Vec<Violation>,
) -> JointPeaks {
    let limits = &lab.limits;
    let joint = j + 1;
    let (vel, vel_at) = peak_of(table.qd, j);
    let (acc, acc_at) = peak_of(table.qdd, j);
    let (jerk, jerk_at) = peak_of(table.jerk, j);
    let step = peak_step(table.q, j);
    let mut over = |rule: Rule, what: &str, unit: &str, (peak, k): (f64, usize), limit: f64| {
        if peak.is_nan() || peak > limit {
            let message = format!(
                "joint {joint} {what} {peak:.4} {unit} at tick {k} ({:.3} s, {}) exceeds the \
                 limit {limit} {unit}",
                table.time_of(k),
                (at.place)(k)
            );
            violations.push(at.violation(rule, message, k, Some(joint), None, None));
        }
    };
    over(Rule::Velocity, "velocity", "rad/s", (vel, vel_at), limits.velocity_rad_s[j]);
    let acc_limit = limits.acceleration_rad_s2[j];
    over(Rule::Acceleration, "acceleration", "rad/s^2", (acc, acc_at), acc_limit);
    over(Rule::Jerk, "jerk", "rad/s^3", (jerk, jerk_at), limits.jerk_rad_s3[j]);
    let what = format!("step between setpoints at {} Hz", table.rate_hz);
    over(Rule::Step, &what, "rad", step, limits.max_step_rad);
    JointPeaks {
        joint,
        min_rad: range.min_rad,
        max_rad: range.max_rad,
        allowed_min_rad: range.allowed_min_rad,
        allowed_max_rad: range.allowed_max_rad,
        peak_velocity: vel,
        velocity_limit: limits.velocity_rad_s[j],
        peak_acceleration: acc,
        acceleration_limit: acc_limit,
        peak_jerk: jerk,
        jerk_limit: limits.jerk_rad_s3[j],
        peak_step_rad: step.0,
        step_limit_rad: limits.max_step_rad,
    }
}

/// The running peak of the TCP's linear speed: (peak, tick, point 0 flange / 1 camera), and
/// the previous tick's positions.
#[derive(Default)]
struct TcpTrack {
    peak: (f64, usize, usize),
    previous: Option<[Point3<f64>; 2]>,
}

impl TcpTrack {
    fn offer(&mut self, k: usize, pose: &PoseClearances, rate_hz: f64) {
        if let Some(prev) = self.previous {
            for (i, (p, before)) in pose.points.iter().zip(prev).enumerate() {
                let v = (p - before).norm() * rate_hz;
                if v.is_nan() || v > self.peak.0 {
                    self.peak = (v, k, i);
                }
            }
        }
        self.previous = Some(pose.points);
    }
}

/// Rule: the flange's and the camera's linear speed stay within `limits.tcp_speed_m_s`.
fn tcp_speed_rule(
    track: &TcpTrack,
    lab: &LabConfig,
    at: &Locator<'_>,
    violations: &mut Vec<Violation>,
) -> TcpSpeed {
    let (peak, k, point) = track.peak;
    let tcp_speed = TcpSpeed {
        peak_m_s: peak,
        point: ["flange", "camera"][point].to_string(),
        tick: k,
        time_s: at.ticks.time_of(k),
        limit_m_s: lab.limits.tcp_speed_m_s,
    };
    if tcp_speed.peak_m_s.is_nan() || tcp_speed.peak_m_s > tcp_speed.limit_m_s {
        let message = format!(
            "TCP linear speed {:.3} m/s ({}) at tick {k} ({:.3} s, {}) exceeds \
             limits.tcp_speed_m_s = {} m/s (the control box stops servo_j with error 60 \
             above {} m/s)",
            tcp_speed.peak_m_s,
            tcp_speed.point,
            tcp_speed.time_s,
            (at.place)(k),
            tcp_speed.limit_m_s,
            crate::lab::SERVO_J_TCP_SPEED_LIMIT
        );
        let capsule = Some(tcp_speed.point.clone());
        violations.push(at.violation(Rule::TcpSpeed, message, k, None, None, capsule));
    }
    tcp_speed
}

/// The running minimum of every clearance: per enclosure face, per keep-out, and the camera to
/// the target.
struct NearestTrack {
    faces: [MinTrack; 6],
    keepouts: [MinTrack; 3],
    camera: MinTrack,
}

impl Default for NearestTrack {
    fn default() -> Self {
        Self { faces: [MinTrack::NONE; 6], keepouts: [MinTrack::NONE; 3], camera: MinTrack::NONE }
    }
}

impl NearestTrack {
    fn offer(&mut self, k: usize, pose: &PoseClearances) {
        for (track, (d, c)) in self.faces.iter_mut().zip(pose.faces) {
            track.offer(d, k, c);
        }
        for (track, (d, c)) in self.keepouts.iter_mut().zip(pose.keepouts) {
            track.offer(d, k, c);
        }
        self.camera.offer(pose.camera_target_m, k, CAPSULE_NAMES.len() - 1);
    }
}

/// Rule: every capsule keeps `margins.wall_m` from each enclosure face and `margins.keepout_m`
/// from each keep-out, and the camera stays `camera.min_target_distance_m` from the target.
fn clearance_rule(
    nearest: &NearestTrack,
    obstacles: &Obstacles,
    lab: &LabConfig,
    at: &Locator<'_>,
    violations: &mut Vec<Violation>,
) -> Vec<Clearance> {
    let mut clearances = Vec::with_capacity(10);
    let mut add = |surface: String, track: MinTrack, required: f64, rule: Rule| {
        let capsule = CAPSULE_NAMES[track.capsule].to_string();
        let k = track.tick;
        let time_s = at.ticks.time_of(k);
        if track.value.is_nan() || track.value < required {
            let what = if rule == Rule::CameraTargetDistance {
                format!(
                    "camera optical centre comes {:.4} m from the target centre (minimum {required} m)",
                    track.value
                )
            } else {
                format!(
                    "capsule '{capsule}' comes {:.4} m from the {surface} (clearance required {required} m)",
                    track.value
                )
            };
            let message = format!("{what} at tick {k} ({time_s:.3} s, {})", (at.place)(k));
            let (s, c) = (Some(surface.clone()), Some(capsule.clone()));
            violations.push(at.violation(rule, message, k, None, s, c));
        }
        clearances.push(Clearance {
            surface,
            min_m: track.value,
            required_m: required,
            tick: k,
            time_s,
            capsule,
        });
    };
    for (f, track) in nearest.faces.iter().enumerate() {
        add(FACE_NAMES[f].to_string(), *track, lab.margins.wall_m, Rule::Wall);
    }
    for (i, track) in nearest.keepouts.iter().enumerate() {
        let surface = format!("keep-out {}", obstacles.keepouts[i].0);
        add(surface, *track, lab.margins.keepout_m, Rule::KeepOut);
    }
    let camera = nearest.camera;
    let required = lab.camera.min_target_distance_m;
    add("camera-target distance".into(), camera, required, Rule::CameraTargetDistance);
    clearances
}

/// Rules a slower playback always cures: per joint, velocity scales with the speed scale `s`,
/// acceleration with `s^2`, jerk with `s^3` and the per-tick step with `s`.
const SCALABLE: [Rule; 6] =
    [Rule::Velocity, Rule::Acceleration, Rule::Jerk, Rule::Step, Rule::TcpSpeed, Rule::CaptureRate];

/// Refuse captures that come faster than the camera follows: `limit_hz` is the camera's
/// (`camera` says which and why, for the message). Records the fastest rate in
/// `report.capture_rate` and adds a [`Rule::CaptureRate`] violation when it is above the limit.
/// The rate scales with the speed scale, so [`speed_scale_to_pass`] covers it.
pub fn check_capture_rate(
    report: &mut PreflightReport,
    table: &SetpointTable,
    limit_hz: f64,
    camera: &str,
) {
    let gaps = table.captures.windows(2).map(|w| (w[1].tick.saturating_sub(w[0].tick), w[1]));
    let Some((gap, at)) = gaps.filter(|(g, _)| *g > 0).min_by_key(|(g, _)| *g) else {
        return;
    };
    let peak_hz = table.rate_hz / gap as f64;
    let time_s = at.tick as f64 * table.dt;
    report.capture_rate =
        Some(CaptureRate { peak_hz, tick: at.tick, time_s, limit_hz, camera: camera.to_string() });
    if peak_hz > limit_hz * (1.0 + 1e-9) {
        report.violations.push(Violation {
            rule: Rule::CaptureRate,
            message: format!(
                "captures come at up to {peak_hz:.1} Hz (every {:.1} ms, at {time_s:.3} s, \
                 waypoint {}), faster than the {limit_hz:.1} Hz {camera}: capture less often \
                 (hitl plan --capture-every) or slow the playback (--speed-scale)",
                1e3 / peak_hz,
                at.waypoint
            ),
            tick: at.tick,
            time_s,
            waypoint: at.waypoint,
            joint: None,
            surface: None,
            capsule: None,
        });
        report.safe = false;
    }
}

/// The largest speed scale at which the file's own ticks meet every scalable limit, when `report`
/// (of `table`) refuses it for velocity, acceleration, jerk, step, TCP speed or capture rate
/// only; `None` when it is safe or refused for anything slowing down cannot be trusted to cure
/// (joint limits, clearances).
///
/// From the scaling laws, over the file's ticks (the lead-in and lead-out are planned within the
/// limits at any scale): `s = time_scale * min(min_j min(v_max/v, sqrt(a_max/a), cbrt(j_max/j),
/// step_max/step), tcp_max/tcp, capture_max/capture)`, `time_scale` being the one the table was built at. The value is exact for the
/// continuous motion; ticks fall at other trajectory times once stretched, so the caller confirms
/// it with a second preflight and steps down slightly when rounding fails it. Ramps do not follow
/// the laws (they are planned within fixed limits from the scaled end state), so a violation in
/// a ramp alone gives the current scale as the start of the caller's search.
pub fn speed_scale_to_pass(
    table: &SetpointTable,
    report: &PreflightReport,
    lab: &LabConfig,
) -> Option<f64> {
    if report.violations.is_empty() || report.violations.iter().any(|v| !SCALABLE.contains(&v.rule))
    {
        return None;
    }
    let file = table.file_ticks();
    let l = &lab.limits;
    let mut factor = f64::INFINITY;
    for j in 0..DOF {
        let peak = |x: &[[f64; DOF]]| x[file.clone()].iter().fold(0.0f64, |m, v| m.max(v[j].abs()));
        let step =
            table.q[file.clone()].windows(2).fold(0.0f64, |m, w| m.max((w[1][j] - w[0][j]).abs()));
        let ratios = [
            l.velocity_rad_s[j] / peak(&table.qd),
            (l.acceleration_rad_s2[j] / peak(&table.qdd)).sqrt(),
            (l.jerk_rad_s3[j] / peak(&table.jerk)).cbrt(),
            l.max_step_rad / step,
        ];
        for r in ratios {
            // A zero peak gives infinity (no constraint); NaN can never pass.
            if r.is_nan() {
                return None;
            }
            factor = factor.min(r);
        }
    }
    // TCP speed and the capture rate scale with the speed scale as joint velocity does.
    let tcp = &report.tcp_speed;
    factor = factor.min(tcp.limit_m_s / tcp.peak_m_s);
    if let Some(c) = &report.capture_rate {
        factor = factor.min(c.limit_hz / c.peak_hz);
    }
    if factor.is_nan() {
        return None;
    }
    // When only a ramp breaks a limit (an end still accelerating near the velocity limit: no
    // jerk-limited stop can avoid adding speed), the file's own bound is no bound: the caller's
    // search starts below the current scale.
    let s = (table.time_scale * factor).min(table.speed_scale);
    (s.is_finite() && s > 0.0).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A pose that looks straight at the default target from 0.29 m, every capsule at least
    /// 0.25 m from the keep-outs.
    const LOOK: [f64; DOF] = [0.0, -0.4, 0.0, 1.4, 0.0, 1.5, 0.0];

    /// Small smooth motion around [`LOOK`], at rest at both ends.
    fn comfortable(n: usize, step: f64, amplitude: f64) -> Trajectory {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * step).collect();
        let span = t[n - 1];
        let qpos = t
            .iter()
            .map(|x| {
                let mut q = LOOK;
                for (j, v) in q.iter_mut().enumerate() {
                    *v += amplitude * (1.0 + j as f64 / 7.0) * (PI * x / span).sin().powi(2);
                }
                q
            })
            .collect();
        Trajectory { qpos, t, ..Default::default() }
    }

    fn run(traj: &Trajectory, lab: &LabConfig, rate: f64) -> PreflightReport {
        let table = SetpointTable::build(traj, rate, 1.0).expect("table");
        check(traj, &table, lab)
    }

    #[test]
    fn a_comfortable_motion_is_safe_in_the_default_lab() {
        let r = run(&comfortable(21, 0.2, 0.1), &LabConfig::default(), 250.0);
        assert!(r.is_safe(), "{:#?}", r.violations);
        assert_eq!(r.clearances.len(), 10);
        assert!(r.clearances.iter().all(|c| c.min_m.is_finite()));
        assert_eq!(r.joints.len(), DOF);
        assert!(r.joints[0].peak_velocity > 0.0);
    }

    #[test]
    fn a_joint_beyond_its_limit_is_named() {
        let mut traj = comfortable(11, 0.2, 0.05);
        // Joint 4's lower limit is -0.10 rad (current arms): push the middle waypoints below it.
        for q in &mut traj.qpos[4..7] {
            q[3] = -0.3;
        }
        let r = run(&traj, &LabConfig::default(), 250.0);
        let v = r.violations.iter().find(|v| v.rule == Rule::JointLimit).expect("limit");
        assert_eq!(v.joint, Some(4));
        assert!(
            v.message.contains("joint 4")
                && v.message.contains("allowed range")
                && v.message.contains("xarm7-current"),
            "{}",
            v.message
        );
        assert_eq!(r.joint_table, "xarm7-current");
    }

    #[test]
    fn the_joint_limits_alone_refuse_as_the_whole_check_does() {
        let mut traj = comfortable(11, 0.2, 0.05);
        for q in &mut traj.qpos[4..7] {
            q[3] = -0.3;
        }
        let lab = LabConfig::default();
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        let whole = check(&traj, &table, &lab);
        let limits: Vec<Violation> =
            whole.violations.into_iter().filter(|v| v.rule == Rule::JointLimit).collect();
        assert_eq!(limits.len(), 1);
        assert_eq!(check_joint_limits(&table, traj.len(), &lab), limits);
        // A motion inside every limit: nothing.
        let calm = comfortable(11, 0.2, 0.05);
        let table = SetpointTable::build(&calm, 250.0, 1.0).expect("table");
        assert!(check_joint_limits(&table, calm.len(), &lab).is_empty());
    }

    #[test]
    fn the_labs_joint_table_decides() {
        // Joint 4 held at -0.10 rad: inside the first arms' table less the default 0.05 rad
        // margin (-0.142), outside the current one's (-0.055).
        let mut traj = comfortable(11, 0.2, 0.0);
        for q in &mut traj.qpos {
            q[3] = -0.10;
        }
        let mut lab = LabConfig::default();
        let r = run(&traj, &lab, 250.0);
        let v = r.violations.iter().find(|v| v.rule == Rule::JointLimit).expect("refused");
        assert_eq!(v.joint, Some(4));
        assert!(v.message.contains("xarm7-current"), "{}", v.message);
        lab.arm.joint_table = crate::joint_table::JointTable::Xarm7Legacy;
        let r = run(&traj, &lab, 250.0);
        assert!(!r.violations.iter().any(|v| v.rule == Rule::JointLimit), "{:#?}", r.violations);
        assert_eq!(r.joint_table, "xarm7-legacy");
    }

    #[test]
    fn a_step_too_large_for_the_rate_is_named() {
        // 0.8 rad/s peak is inside the velocity limit but makes 0.016 rad steps at 50 Hz.
        let mut traj = comfortable(3, 0.5, 0.0);
        traj.t = vec![0.0, 1.0, 2.0];
        traj.qpos[1][0] = 0.5;
        let mut lab = LabConfig::default();
        lab.limits.jerk_rad_s3 = [1000.0; DOF];
        lab.limits.acceleration_rad_s2 = [100.0; DOF];
        let r = run(&traj, &lab, 50.0);
        let rules: Vec<Rule> = r.violations.iter().map(|v| v.rule).collect();
        assert_eq!(rules, vec![Rule::Step], "{:#?}", r.violations);
        assert!(r.violations[0].message.contains("50 Hz"));
        // The same motion at 250 Hz makes small steps.
        assert!(run(&traj, &lab, 250.0).is_safe());
    }

    /// Joint 1 swings the outstretched arm 0.8 rad in 1 s: inside every joint limit of a lab
    /// that allows 2 rad/s, but the flange, ~0.5 m out, peaks near 0.75 m/s.
    fn swing_of_the_outstretched_arm() -> (Trajectory, LabConfig) {
        let mut traj = comfortable(3, 0.5, 0.0);
        traj.t = vec![0.0, 1.0, 2.0];
        traj.qpos[1][0] = 0.8;
        let mut lab = LabConfig::default();
        lab.limits.velocity_rad_s = [2.0; DOF];
        lab.limits.acceleration_rad_s2 = [100.0; DOF];
        lab.limits.jerk_rad_s3 = [1000.0; DOF];
        lab.limits.max_step_rad = 0.1;
        (traj, lab)
    }

    #[test]
    fn the_tcp_speed_is_checked_against_the_lab() {
        let (traj, mut lab) = swing_of_the_outstretched_arm();
        let r = run(&traj, &lab, 250.0);
        assert!(r.is_safe(), "{:#?}", r.violations);
        let peak = r.tcp_speed.peak_m_s;
        // The analytic peak: |r x w| for the farther point, at the quintic's peak speed 1.875 x.
        let reach = |p: nalgebra::Vector3<f64>| p.x.hypot(p.y);
        let flange = reach(kinematics::flange_pose(&LOOK).translation.vector);
        let cam = reach(kinematics::camera_pose(&LOOK, &lab.camera_mount()).translation.vector);
        assert!(peak > 0.3 && peak < 1.875 * 0.8 * flange.max(cam) * 1.05, "{peak}");
        lab.limits.tcp_speed_m_s = 0.5 * peak;
        let r = run(&traj, &lab, 250.0);
        let rules: Vec<Rule> = r.violations.iter().map(|v| v.rule).collect();
        assert_eq!(rules, vec![Rule::TcpSpeed], "{:#?}", r.violations);
        assert!(
            r.violations[0].message.contains("TCP linear speed"),
            "{}",
            r.violations[0].message
        );
        assert!(r.violations[0].message.contains("error 60"), "{}", r.violations[0].message);
    }

    #[test]
    fn walls_and_keepouts_are_checked_per_capsule() {
        // Move the arm base next to the x- wall: the links must come too close to it.
        let mut lab = LabConfig::default();
        lab.arm.base_in_lab_m[0] = 0.1;
        let r = run(&comfortable(5, 0.2, 0.0), &lab, 250.0);
        let v = r.violations.iter().find(|v| v.rule == Rule::Wall).expect("wall");
        assert_eq!(v.surface.as_deref(), Some("wall x-"));
        // And put the target keep-out where the hand is.
        let mut lab = LabConfig::default();
        let hand = kinematics::flange_pose(&LOOK).translation.vector;
        lab.target.position_base_m = [hand.x, hand.y, hand.z];
        let r = run(&comfortable(5, 0.2, 0.0), &lab, 250.0);
        let rules: Vec<Rule> = r.violations.iter().map(|v| v.rule).collect();
        assert!(rules.contains(&Rule::KeepOut), "{rules:?}");
        assert!(rules.contains(&Rule::CameraTargetDistance), "{rules:?}");
        let floor = r.clearances.iter().find(|c| c.surface == "floor").expect("floor");
        assert_ne!(floor.capsule, "base", "the base capsule is exempt from the floor");
    }

    #[test]
    fn the_tcp_speed_has_a_speed_scale_remedy() {
        // The motion of the TCP test, refused for TCP speed alone.
        let (traj, mut lab) = swing_of_the_outstretched_arm();
        let peak = run(&traj, &lab, 250.0).tcp_speed.peak_m_s;
        lab.limits.tcp_speed_m_s = 0.5 * peak;
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        let r = check(&traj, &table, &lab);
        let s = speed_scale_to_pass(&table, &r, &lab).expect("a remedy");
        assert!((s - 0.5).abs() < 0.02, "{s}");
        let slower = SetpointTable::build(&traj, 250.0, s * 0.99).expect("table");
        assert!(check(&traj, &slower, &lab).is_safe());
    }

    #[test]
    fn captures_faster_than_the_camera_follows_are_refused_with_a_remedy() {
        // 2 s, a capture every 0.04 s: 25 Hz.
        let n = 51;
        let mut traj = comfortable(n, 0.04, 0.02);
        traj.capture = Some(vec![true; n]);
        let lab = LabConfig::default();
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        let mut r = check(&traj, &table, &lab);
        assert!(r.is_safe(), "{:#?}", r.violations);
        check_capture_rate(&mut r, &table, 15.0, "camera's limit");
        let rate = r.capture_rate.clone().expect("recorded");
        assert!((rate.peak_hz - 25.0).abs() < 1e-9, "{rate:?}");
        let rules: Vec<Rule> = r.violations.iter().map(|v| v.rule).collect();
        assert_eq!(rules, vec![Rule::CaptureRate]);
        assert!(r.violations[0].message.contains("25.0 Hz"), "{}", r.violations[0].message);
        let s = speed_scale_to_pass(&table, &r, &lab).expect("a remedy");
        assert!((s - 0.6).abs() < 1e-9, "{s}");
        // 10 Hz captures pass.
        let mut traj = comfortable(n, 0.1, 0.02);
        traj.capture = Some(vec![true; n]);
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        let mut r = check(&traj, &table, &lab);
        check_capture_rate(&mut r, &table, 15.0, "camera's limit");
        assert!(r.is_safe(), "{:#?}", r.violations);
    }
}
