//! Time parametrisation: from waypoints `(t, qpos)` to the setpoint table the control loop plays,
//! one setpoint per tick at the control rate, with position, velocity, acceleration and jerk per
//! joint (see `docs/time-parametrisation.md`).
//!
//! **Interpolation.** Each joint follows a piecewise quintic (fifth-degree) Hermite curve through
//! every waypoint at its time. At each waypoint the curve takes a velocity and an acceleration
//! shared by the segments on both sides, so position, velocity and acceleration are continuous
//! (C2) and jerk is bounded (a polynomial on each segment, stepping only at waypoints). The knot
//! velocities and accelerations are those of the clamped cubic spline through the waypoints,
//! clamped at each end to the file's own velocity: zero for a file at rest there (on interior
//! segments the quintic then *is* that cubic spline, the smoothest C2 interpolant). The end
//! knots take the file's own acceleration (zero at rest); on the first and last segments the
//! quintic is the minimum-jerk curve meeting those end conditions. A file that starts or ends
//! moving (its end state estimated from its end waypoints, see `boundary`) thus plays its own
//! motion to its ends; the controller adds a lead-in from rest and a lead-out to rest
//! ([`SetpointTable::with_ramps`]), and files at rest at both ends play exactly as before. Setpoints are evaluated analytically (no
//! numerical integration, no accumulated error). Like every spline, it can swing a little past a
//! waypoint next to a sharp corner in the data (a few percent of the step, decaying over a few
//! segments); preflight checks every tick, so such a swing can never reach a limit unnoticed.
//!
//! **Why this is safe for servo mode.** The xArm in servo mode executes each `servo_j` at once, at
//! full speed, ignoring speed arguments: the host must stream small, smooth steps at a steady
//! rate. Here each step is `qd * dt` to first order, so bounding `|qd|` bounds the step;
//! continuous acceleration means no velocity jumps between ticks (the shaking users report with
//! jerky host streams); rest-to-rest ends (or ramps to rest) mean the stream starts and ends
//! where the arm is at rest. [`crate::preflight`] checks every tick of this table (step, velocity, acceleration,
//! jerk, limits, clearances) before anything moves.
//!
//! **Time.** A speed scale `s` in (0, 1] stretches time (`t' = t / s`), so velocities scale by
//! `s`, accelerations by `s^2`, jerk by `s^3`. The duration is then rounded up to a whole number
//! of ticks by stretching time a little more (never speeding up), so the last setpoint falls on a
//! tick and equals the last waypoint exactly. Setpoint `k` depends only on the trajectory, the
//! rate and the scale: no clock is read, two builds give identical tables.

use crate::kinematics::{Joints, DOF};
use crate::npz::{self, NpzError};
use crate::trajectory::Trajectory;
use hitl_hal::JointState;
use serde::{Deserialize, Serialize};

/// Default control rate, Hz.
pub const DEFAULT_RATE_HZ: f64 = 250.0;
/// Lowest and highest control rate accepted, Hz.
pub const RATE_RANGE_HZ: (f64, f64) = (50.0, 1000.0);

/// The most servo_j setpoints per second an xArm control box takes (UFACTORY: servo mode
/// accepts commands at up to 250 Hz). `hitl run` refuses a faster rate (`hitl check` checks
/// any rate in [`RATE_RANGE_HZ`]: it moves nothing).
pub const XARM_MAX_SERVO_RATE_HZ: f64 = 250.0;
/// Most ticks in a table (~2.2 h at 250 Hz; ~450 MB of setpoints). Longer runs are refused.
pub const MAX_TICKS: usize = 2_000_000;

/// Why a setpoint table could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TimingError {
    #[error("control rate {0} Hz is outside 50-1000 Hz")]
    Rate(f64),
    #[error("speed scale {0} is outside (0, 1]")]
    SpeedScale(f64),
    #[error("the trajectory lasts {duration_s:.1} s at this rate and scale: {ticks} ticks, more than the {max} allowed")]
    TooLong { duration_s: f64, ticks: f64, max: usize },
    #[error(transparent)]
    Trajectory(#[from] NpzError),
}

/// A capture waypoint and the tick it fires at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Capture {
    pub waypoint: usize,
    pub tick: usize,
}

/// The preallocated setpoint stream: entry `k` of each vector is tick `k`, at `k * dt` seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct SetpointTable {
    /// Control rate, Hz.
    pub rate_hz: f64,
    /// Tick period, seconds (`1 / rate_hz`).
    pub dt: f64,
    /// The speed scale asked for.
    pub speed_scale: f64,
    /// Trajectory seconds per playback second: `speed_scale`, a little less after rounding the
    /// duration up to whole ticks. Velocities are `dq/dt * time_scale`.
    pub time_scale: f64,
    /// Playback duration, seconds: `(ticks - 1) * dt`.
    pub duration_s: f64,
    /// Joint positions, radians.
    pub q: Vec<Joints>,
    /// Joint velocities, rad/s.
    pub qd: Vec<Joints>,
    /// Joint accelerations, rad/s^2.
    pub qdd: Vec<Joints>,
    /// Joint jerks, rad/s^3.
    pub jerk: Vec<Joints>,
    /// The tick nearest each waypoint.
    pub waypoint_ticks: Vec<usize>,
    /// Capture waypoints in order, with their ticks.
    pub captures: Vec<Capture>,
    /// Light level per tick: the level of the latest waypoint whose tick is at or before this
    /// one (held, not blended). `None` when the trajectory has no light schedule.
    pub light: Option<Vec<f32>>,
    /// Ticks of lead-in before the first waypoint's tick: a planned move from rest into the
    /// file's first state (0 when the file starts at rest). See [`SetpointTable::with_ramps`].
    pub lead_in_ticks: usize,
    /// Ticks of lead-out after the last waypoint's tick, ending at rest (0 when the file ends at
    /// rest).
    pub lead_out_ticks: usize,
}

impl SetpointTable {
    /// Build the table for `traj` at `rate_hz`, slowed by `speed_scale`.
    pub fn build(
        traj: &Trajectory,
        rate_hz: f64,
        speed_scale: f64,
    ) -> Result<SetpointTable, TimingError> {
        if !(rate_hz >= RATE_RANGE_HZ.0 && rate_hz <= RATE_RANGE_HZ.1) {
            return Err(TimingError::Rate(rate_hz));
        }
        if !(speed_scale > 0.0 && speed_scale <= 1.0) {
            return Err(TimingError::SpeedScale(speed_scale));
        }
        npz::validate(traj)?;
        let dt = 1.0 / rate_hz;
        let t0 = traj.t[0];
        let span = traj.t[traj.t.len() - 1] - t0;
        let stretched = span / speed_scale;
        let exact = stretched / dt;
        if exact.is_nan() || exact >= MAX_TICKS as f64 {
            return Err(TimingError::TooLong {
                duration_s: stretched,
                ticks: exact,
                max: MAX_TICKS,
            });
        }
        // Whole ticks, rounding up; a value within rounding noise of an integer is that integer.
        let steps = if (exact - exact.round()).abs() <= 1e-9 * exact.max(1.0) {
            exact.round()
        } else {
            exact.ceil()
        }
        .max(1.0) as usize;
        let duration_s = steps as f64 * dt;
        let time_scale = span / duration_s;
        let ticks = steps + 1;

        let knots = Knots::new(traj, boundary(traj, true), boundary(traj, false));
        let mut q = Vec::with_capacity(ticks);
        let mut qd = Vec::with_capacity(ticks);
        let mut qdd = Vec::with_capacity(ticks);
        let mut jerk = Vec::with_capacity(ticks);
        let mut seg = 0usize;
        let mut poly = knots.segment(traj, 0);
        let last = traj.t.len() - 1;
        for k in 0..ticks {
            // Trajectory time of tick k (relative to t0); the last tick is the last waypoint.
            let tt = if k == steps { span } else { k as f64 * dt * time_scale };
            while seg + 1 < last && tt >= traj.t[seg + 1] - t0 {
                seg += 1;
                poly = knots.segment(traj, seg);
            }
            if k == steps {
                q.push(traj.qpos[last]);
                qd.push(knots.v[last].map(|x| x * time_scale));
                qdd.push(knots.a[last].map(|x| x * time_scale * time_scale));
                let (_, _, _, j) = poly.eval(1.0);
                jerk.push(j.map(|x| x * time_scale.powi(3)));
                continue;
            }
            let u = ((tt - (traj.t[seg] - t0)) / poly.h).clamp(0.0, 1.0);
            let (p, v, a, j) = poly.eval(u);
            q.push(p);
            qd.push(v.map(|x| x * time_scale));
            qdd.push(a.map(|x| x * time_scale * time_scale));
            jerk.push(j.map(|x| x * time_scale.powi(3)));
        }

        let tick_of = |t: f64| (((t - t0) / time_scale / dt).round() as usize).min(steps);
        let waypoint_ticks: Vec<usize> = traj.t.iter().map(|t| tick_of(*t)).collect();
        let captures = traj
            .capture
            .as_ref()
            .map(|c| {
                c.iter()
                    .enumerate()
                    .filter(|(_, on)| **on)
                    .map(|(i, _)| Capture { waypoint: i, tick: waypoint_ticks[i] })
                    .collect()
            })
            .unwrap_or_default();
        let light = traj.light.as_ref().map(|levels| {
            let mut out = Vec::with_capacity(ticks);
            let mut w = 0usize;
            for k in 0..ticks {
                while w + 1 < levels.len() && waypoint_ticks[w + 1] <= k {
                    w += 1;
                }
                out.push(levels[w]);
            }
            out
        });
        Ok(SetpointTable {
            rate_hz,
            dt,
            speed_scale,
            time_scale,
            duration_s,
            q,
            qd,
            qdd,
            jerk,
            waypoint_ticks,
            captures,
            light,
            lead_in_ticks: 0,
            lead_out_ticks: 0,
        })
    }

    /// The ticks that play the file's own waypoints (the lead-in and lead-out excluded).
    pub fn file_ticks(&self) -> std::ops::Range<usize> {
        self.lead_in_ticks..self.ticks() - self.lead_out_ticks
    }

    /// The commanded state at tick `k`.
    pub fn state(&self, k: usize) -> JointState {
        JointState { q: self.q[k], qd: self.qd[k], qdd: self.qdd[k] }
    }

    /// The file's first state (its first waypoint's tick), in playback time.
    pub fn file_start(&self) -> JointState {
        self.state(self.file_ticks().start)
    }

    /// The file's last state (its last waypoint's tick), in playback time.
    pub fn file_end(&self) -> JointState {
        self.state(self.file_ticks().end - 1)
    }

    /// Splice a lead-in before the file's first tick and a lead-out after its last: `lead_in`
    /// ends one tick before the file's first state (its first sample at rest), `lead_out` starts
    /// one tick after the file's last state (its last sample at rest). Jerk on ramp ticks is the
    /// backward difference of acceleration (the planner's own jerk is bounded by its limit, so
    /// this is too). Waypoint and capture ticks move by the lead-in; the light holds its first
    /// level through the lead-in and its last through the lead-out. The file's ticks keep their
    /// values bit for bit.
    pub fn with_ramps(mut self, lead_in: &[JointState], lead_out: &[JointState]) -> Self {
        let (n_in, n_out) = (lead_in.len(), lead_out.len());
        if n_in == 0 && n_out == 0 {
            return self;
        }
        let dt = self.dt;
        let ramp_jerk = |prev: &Joints, a: &Joints| -> Joints {
            std::array::from_fn(|j| (a[j] - prev[j]) / dt)
        };
        let total = self.ticks() + n_in + n_out;
        let (mut q, mut qd, mut qdd, mut jerk) = (
            Vec::with_capacity(total),
            Vec::with_capacity(total),
            Vec::with_capacity(total),
            Vec::with_capacity(total),
        );
        let mut prev_a = [0.0; DOF];
        for s in lead_in {
            q.push(s.q);
            qd.push(s.qd);
            qdd.push(s.qdd);
            jerk.push(ramp_jerk(&prev_a, &s.qdd));
            prev_a = s.qdd;
        }
        q.append(&mut self.q);
        qd.append(&mut self.qd);
        qdd.append(&mut self.qdd);
        jerk.append(&mut self.jerk);
        let mut prev_a = qdd.last().copied().unwrap_or([0.0; DOF]);
        for s in lead_out {
            q.push(s.q);
            qd.push(s.qd);
            qdd.push(s.qdd);
            jerk.push(ramp_jerk(&prev_a, &s.qdd));
            prev_a = s.qdd;
        }
        for w in &mut self.waypoint_ticks {
            *w += n_in;
        }
        for c in &mut self.captures {
            c.tick += n_in;
        }
        if let Some(light) = &mut self.light {
            let (first, last) = (light[0], light[light.len() - 1]);
            let mut out = Vec::with_capacity(total);
            out.extend(std::iter::repeat_n(first, n_in));
            out.append(light);
            out.extend(std::iter::repeat_n(last, n_out));
            *light = out;
        }
        self.q = q;
        self.qd = qd;
        self.qdd = qdd;
        self.jerk = jerk;
        self.lead_in_ticks += n_in;
        self.lead_out_ticks += n_out;
        self.duration_s = (total - 1) as f64 * dt;
        self
    }

    /// Number of ticks (setpoints).
    pub fn ticks(&self) -> usize {
        self.q.len()
    }

    /// Playback time of tick `k`, seconds.
    pub fn time_of(&self, tick: usize) -> f64 {
        tick as f64 * self.dt
    }
}

/// The file's own velocity and acceleration at one end, per joint, in trajectory time.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Boundary {
    v: Joints,
    a: Joints,
}

/// Fewest waypoints from which an end's motion is estimated; shorter files are taken at rest.
const BOUNDARY_POINTS: usize = 5;
/// Below these an end joint is at rest whatever the data says, rad/s and rad/s^2 (numerical
/// noise of exact rest data).
const REST_FLOOR: (f64, f64) = (1e-9, 1e-7);
/// An end velocity or acceleration is taken from the data when it is this many times its
/// estimation error (known to about 1 %).
const BOUNDARY_TRUST: f64 = 100.0;

/// The file's own velocity and acceleration at its start (`start`) or end, or `None` when the
/// data does not pin them down well: that end plays rest to rest, as always.
///
/// The estimate is the derivative at the end of the cubic through the four end waypoints (Newton
/// divided differences, any spacing). Its error is about the fourth divided difference `D` of the
/// five end waypoints times the node products: `|D| |d1 d2 d3|` for the velocity and
/// `2 |D| |d1 d2 + d1 d3 + d2 d3|` for the acceleration (`di` the times of waypoints 1..3 from the
/// end). A joint's velocity (acceleration) is taken when it exceeds [`BOUNDARY_TRUST`] times its
/// error and [`REST_FLOOR`], else it is zero; the end moves when any joint's does. Densely
/// sampled motion (a pipeline's 100 Hz: errors ~1e-8) is taken as written; coarse hand-made
/// waypoints, whose ends the data cannot resolve to a percent, stay rest to rest (pinning their
/// ends costs little: the jerk it adds scales with the end state over the end segment's length).
fn boundary(traj: &Trajectory, start: bool) -> Option<Boundary> {
    let n = traj.t.len();
    if n < BOUNDARY_POINTS {
        return None;
    }
    let idx: [usize; BOUNDARY_POINTS] = std::array::from_fn(|i| if start { i } else { n - 1 - i });
    let x: [f64; BOUNDARY_POINTS] = idx.map(|i| traj.t[i]);
    let d = [x[0] - x[1], x[0] - x[2], x[0] - x[3]];
    let err_v = (d[0] * d[1] * d[2]).abs();
    let err_a = 2.0 * (d[0] * d[1] + d[0] * d[2] + d[1] * d[2]).abs();
    let mut out = Boundary { v: [0.0; DOF], a: [0.0; DOF] };
    let mut moving = false;
    for j in 0..DOF {
        // Divided-difference table, in place.
        let mut c: [f64; BOUNDARY_POINTS] = idx.map(|i| traj.qpos[i][j]);
        for level in 1..BOUNDARY_POINTS {
            for i in (level..BOUNDARY_POINTS).rev() {
                c[i] = (c[i] - c[i - 1]) / (x[i] - x[i - level]);
            }
        }
        let v = c[1] + c[2] * d[0] + c[3] * d[0] * d[1];
        let a = 2.0 * c[2] + 2.0 * c[3] * (d[0] + d[1]);
        let tol_v = (BOUNDARY_TRUST * c[4].abs() * err_v).max(REST_FLOOR.0);
        let tol_a = (BOUNDARY_TRUST * c[4].abs() * err_a).max(REST_FLOOR.1);
        if v.abs() > tol_v {
            out.v[j] = v;
            moving = true;
        }
        if a.abs() > tol_a {
            out.a[j] = a;
            moving = true;
        }
    }
    moving.then_some(out)
}

/// Velocity and acceleration at every waypoint, per joint (in trajectory time).
struct Knots {
    v: Vec<Joints>,
    a: Vec<Joints>,
}

impl Knots {
    /// Knot velocities and accelerations of the clamped cubic spline through the waypoints, its
    /// end velocities clamped to the file's own (see [`boundary`]; zero at an end at rest), and
    /// the file's own accelerations at both ends (zero at an end at rest).
    fn new(traj: &Trajectory, start: Option<Boundary>, end: Option<Boundary>) -> Self {
        let n = traj.t.len();
        let h: Vec<f64> = traj.t.windows(2).map(|w| w[1] - w[0]).collect();
        let mut v = vec![[0.0; DOF]; n];
        let mut a = vec![[0.0; DOF]; n];
        // Scratch for the tridiagonal solve (Thomas algorithm), reused per joint.
        let mut diag = vec![0.0; n];
        let mut rhs = vec![0.0; n];
        let mut m = vec![0.0; n];
        for j in 0..DOF {
            let d = |i: usize| (traj.qpos[i + 1][j] - traj.qpos[i][j]) / h[i];
            // Row i: sub[i] m[i-1] + diag[i] m[i] + sup[i] m[i+1] = rhs[i], with
            // sub[i] = h[i-1], sup[i] = h[i]; rows 0 and n-1 are the clamped ends.
            for i in 0..n {
                let (sub, sup) =
                    (if i > 0 { h[i - 1] } else { 0.0 }, if i + 1 < n { h[i] } else { 0.0 });
                diag[i] = 2.0 * (sub + sup);
                rhs[i] =
                    6.0 * (if i + 1 < n { d(i) } else { 0.0 } - if i > 0 { d(i - 1) } else { 0.0 });
            }
            // Clamped ends: the first and last rows take the end velocities.
            if let Some(b) = &start {
                rhs[0] -= 6.0 * b.v[j];
            }
            if let Some(b) = &end {
                rhs[n - 1] += 6.0 * b.v[j];
            }
            // Forward sweep.
            for i in 1..n {
                let w = h[i - 1] / diag[i - 1];
                diag[i] -= w * h[i - 1];
                rhs[i] -= w * rhs[i - 1];
            }
            // Back substitution.
            m[n - 1] = rhs[n - 1] / diag[n - 1];
            for i in (0..n - 1).rev() {
                m[i] = (rhs[i] - h[i] * m[i + 1]) / diag[i];
            }
            for i in 1..n - 1 {
                v[i][j] = d(i) - h[i] * (2.0 * m[i] + m[i + 1]) / 6.0;
                a[i][j] = m[i];
            }
        }
        for (b, i) in [(start, 0), (end, n - 1)] {
            if let Some(b) = b {
                v[i] = b.v;
                a[i] = b.a;
            }
        }
        Knots { v, a }
    }

    /// The quintic of segment `i` (waypoint i to i+1) for every joint.
    fn segment(&self, traj: &Trajectory, i: usize) -> Quintic {
        let h = traj.t[i + 1] - traj.t[i];
        let mut c = [[0.0; 6]; DOF];
        for (j, cj) in c.iter_mut().enumerate() {
            let p0 = traj.qpos[i][j];
            let d = traj.qpos[i + 1][j] - p0;
            let (v0, v1) = (self.v[i][j] * h, self.v[i + 1][j] * h);
            let (a0, a1) = (self.a[i][j] * h * h, self.a[i + 1][j] * h * h);
            *cj = [
                p0,
                v0,
                0.5 * a0,
                10.0 * d - 6.0 * v0 - 4.0 * v1 - 1.5 * a0 + 0.5 * a1,
                -15.0 * d + 8.0 * v0 + 7.0 * v1 + 1.5 * a0 - a1,
                6.0 * d - 3.0 * v0 - 3.0 * v1 - 0.5 * a0 + 0.5 * a1,
            ];
        }
        Quintic { h, c }
    }
}

/// One segment's quintics in the normalised time `u = (t - t_i) / h`, one per joint.
struct Quintic {
    h: f64,
    c: [[f64; 6]; DOF],
}

impl Quintic {
    /// Position, velocity, acceleration, jerk at `u` (per second of trajectory time).
    fn eval(&self, u: f64) -> (Joints, Joints, Joints, Joints) {
        let (mut p, mut v, mut a, mut j) = ([0.0; DOF], [0.0; DOF], [0.0; DOF], [0.0; DOF]);
        let h = self.h;
        for (k, c) in self.c.iter().enumerate() {
            p[k] = c[0] + u * (c[1] + u * (c[2] + u * (c[3] + u * (c[4] + u * c[5]))));
            v[k] = (c[1] + u * (2.0 * c[2] + u * (3.0 * c[3] + u * (4.0 * c[4] + u * 5.0 * c[5]))))
                / h;
            a[k] = (2.0 * c[2] + u * (6.0 * c[3] + u * (12.0 * c[4] + u * 20.0 * c[5]))) / (h * h);
            j[k] = (6.0 * c[3] + u * (24.0 * c[4] + u * 60.0 * c[5])) / (h * h * h);
        }
        (p, v, a, j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth test trajectory near a comfortable pose, at rest at both ends: each joint moves
    /// by `A sin^4(m pi t / T)`, with waypoints every `step` seconds.
    fn wavy(n: usize, step: f64) -> Trajectory {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * step).collect();
        let span = t[n - 1];
        let qpos = t
            .iter()
            .map(|x| {
                let mut q = [0.0, 0.3, 0.0, 1.2, 0.0, 0.9, 0.0];
                for (j, v) in q.iter_mut().enumerate() {
                    let m = 1.0 + (j % 2) as f64;
                    let sign = if j % 3 == 0 { -1.0 } else { 1.0 };
                    *v += sign * 0.15 * (m * std::f64::consts::PI * x / span).sin().powi(4);
                }
                q
            })
            .collect();
        Trajectory { qpos, t, ..Default::default() }
    }

    #[test]
    fn passes_through_every_waypoint_and_ends_on_the_last() {
        let traj = wavy(21, 0.1);
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        assert_eq!(table.ticks(), 501);
        for (i, k) in table.waypoint_ticks.iter().enumerate() {
            assert_eq!(*k, i * 25);
            for j in 0..DOF {
                assert!((table.q[*k][j] - traj.qpos[i][j]).abs() < 1e-9, "waypoint {i} joint {j}");
            }
        }
        assert_eq!(table.q.last(), traj.qpos.last());
        assert_eq!(table.q[0], traj.qpos[0]);
    }

    #[test]
    fn rest_to_rest_at_both_ends() {
        let table = SetpointTable::build(&wavy(11, 0.2), 500.0, 1.0).expect("table");
        let last = table.ticks() - 1;
        for j in 0..DOF {
            for k in [0, last] {
                assert!(table.qd[k][j].abs() < 1e-12, "qd tick {k} joint {j}");
                assert!(table.qdd[k][j].abs() < 1e-9, "qdd tick {k} joint {j}");
            }
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        // Central differences of q, qd, qdd against qd, qdd, jerk, within the Taylor bounds set
        // by the table's own peak jerk (jerk steps at waypoints, so its own check skips the
        // ticks next to a waypoint).
        let table = SetpointTable::build(&wavy(16, 0.1), 1000.0, 1.0).expect("table");
        let dt = table.dt;
        let peak_jerk = table.jerk.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(peak_jerk > 1.0 && peak_jerk < 1000.0, "{peak_jerk}");
        let near_knot = |k: usize| table.waypoint_ticks.iter().any(|w| w.abs_diff(k) <= 1);
        let mut worst = [0.0f64; 3];
        for k in 1..table.ticks() - 1 {
            for j in 0..DOF {
                let fd = |x: &Vec<Joints>| (x[k + 1][j] - x[k - 1][j]) / (2.0 * dt);
                worst[0] = worst[0].max((fd(&table.q) - table.qd[k][j]).abs());
                worst[1] = worst[1].max((fd(&table.qd) - table.qdd[k][j]).abs());
                if !near_knot(k) {
                    worst[2] = worst[2].max((fd(&table.qdd) - table.jerk[k][j]).abs());
                }
            }
        }
        assert!(worst[0] <= dt * dt / 6.0 * peak_jerk * 1.01 + 1e-12, "velocity {worst:?}");
        assert!(worst[1] <= dt / 2.0 * peak_jerk * 1.01 + 1e-9, "acceleration {worst:?}");
        assert!(worst[2] <= 1e-3 * peak_jerk, "jerk {worst:?}");
    }

    #[test]
    fn acceleration_is_continuous_across_waypoints() {
        let table = SetpointTable::build(&wavy(16, 0.1), 1000.0, 1.0).expect("table");
        let peak_jerk = table.jerk.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        for k in 1..table.ticks() {
            for j in 0..DOF {
                let jump = (table.qdd[k][j] - table.qdd[k - 1][j]).abs();
                assert!(jump <= peak_jerk * table.dt * 1.0001 + 1e-12, "tick {k} joint {j}");
            }
        }
    }

    #[test]
    fn speed_scale_stretches_time_and_slows_motion() {
        let traj = wavy(11, 0.1);
        let full = SetpointTable::build(&traj, 250.0, 1.0).expect("full");
        let half = SetpointTable::build(&traj, 250.0, 0.5).expect("half");
        assert!((full.duration_s - 1.0).abs() < 1e-12);
        assert!((half.duration_s - 2.0).abs() < 1e-12);
        assert_eq!(half.ticks(), 2 * full.ticks() - 1);
        for k in 0..full.ticks() {
            for j in 0..DOF {
                assert!((half.q[2 * k][j] - full.q[k][j]).abs() < 1e-12);
                assert!((half.qd[2 * k][j] - 0.5 * full.qd[k][j]).abs() < 1e-12);
                assert!((half.qdd[2 * k][j] - 0.25 * full.qdd[k][j]).abs() < 1e-9);
            }
        }
        assert_eq!(half.q.last(), traj.qpos.last());
    }

    #[test]
    fn uneven_duration_rounds_up_to_whole_ticks() {
        let mut traj = wavy(3, 0.1);
        traj.t = vec![0.0, 0.1, 0.2013];
        let table = SetpointTable::build(&traj, 100.0, 1.0).expect("table");
        assert_eq!(table.ticks(), 22);
        assert!(table.duration_s >= 0.2013 && table.time_scale <= 1.0);
        assert_eq!(table.q.last(), traj.qpos.last());
    }

    #[test]
    fn a_sharp_step_swings_only_a_little_past_its_waypoints() {
        // A joint that rises then holds: the spline may swing past the hold value, a little.
        let t: Vec<f64> = (0..8).map(|i| i as f64 * 0.25).collect();
        let rise = [0.0, 0.0, 0.1, 0.5, 0.9, 1.0, 1.0, 1.0];
        let qpos = rise.iter().map(|r| [*r; DOF]).collect();
        let table = SetpointTable::build(&Trajectory { qpos, t, ..Default::default() }, 250.0, 1.0)
            .expect("table");
        let (lo, hi) =
            table.q.iter().fold((f64::MAX, f64::MIN), |(l, h), q| (l.min(q[0]), h.max(q[0])));
        eprintln!("step 0 -> 1 spans {lo}..{hi}");
        assert!(lo >= -0.05 && hi <= 1.05, "range {lo}..{hi}");
    }

    #[test]
    fn captures_and_light_land_on_their_ticks() {
        let mut traj = wavy(5, 0.1);
        traj.capture = Some(vec![false, true, false, true, false]);
        traj.light = Some(vec![0.0, 0.5, 0.5, 1.0, 1.0]);
        let table = SetpointTable::build(&traj, 250.0, 0.5).expect("table");
        assert_eq!(
            table.captures,
            vec![Capture { waypoint: 1, tick: 50 }, Capture { waypoint: 3, tick: 150 }]
        );
        let light = table.light.expect("light");
        assert_eq!((light[49], light[50], light[149], light[150]), (0.0, 0.5, 0.5, 1.0));
    }

    /// A joint-1 sine around a comfortable pose, `hz` waypoints per second over `span` seconds,
    /// starting at phase `phase`: moving at both ends.
    fn sine(hz: f64, span: f64, phase: f64) -> (Trajectory, impl Fn(f64) -> (f64, f64, f64)) {
        let (amp, w) = (0.1, 2.0 * std::f64::consts::PI * 0.2);
        let n = (span * hz).round() as usize + 1;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / hz).collect();
        let qpos = t
            .iter()
            .map(|x| {
                let mut q = [0.0, 0.3, 0.0, 1.2, 0.0, 0.9, 0.0];
                q[0] = amp * (w * x + phase).sin();
                q
            })
            .collect();
        let exact = move |x: f64| {
            let a = w * x + phase;
            (amp * a.sin(), amp * w * a.cos(), -amp * w * w * a.sin())
        };
        (Trajectory { qpos, t, ..Default::default() }, exact)
    }

    #[test]
    fn a_file_that_starts_and_ends_moving_plays_its_own_motion_to_the_ends() {
        // 0.1 rad, 0.2 Hz, 100 Hz samples, 6 s: moving at 0.126 rad/s at both ends.
        let (traj, exact) = sine(100.0, 6.0, 0.0);
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        assert_eq!((table.lead_in_ticks, table.lead_out_ticks), (0, 0));
        let mut worst = [0.0f64; 3];
        for k in 0..table.ticks() {
            let (p, v, a) = exact(table.time_of(k));
            worst[0] = worst[0].max((table.q[k][0] - p).abs());
            worst[1] = worst[1].max((table.qd[k][0] - v).abs());
            worst[2] = worst[2].max((table.qdd[k][0] - a).abs());
        }
        assert!(worst[0] < 1e-9 && worst[1] < 1e-6 && worst[2] < 1e-3, "{worst:?}");
        // The ends carry the file's own velocity; jerk stays near the sine's 0.2 rad/s^3.
        assert!((table.qd[0][0] - exact(0.0).1).abs() < 1e-6);
        let peak_jerk = table.jerk.iter().fold(0.0f64, |m, j| m.max(j[0].abs()));
        assert!(peak_jerk < 1.0, "{peak_jerk}");
        // The other joints hold still: exactly at rest.
        assert!(table.qd.iter().all(|v| v[1..].iter().all(|x| *x == 0.0)));
    }

    #[test]
    fn a_file_that_ends_at_rest_with_acceleration_keeps_its_acceleration() {
        // Starts at a crest (velocity 0, acceleration -0.158 rad/s^2), ends moving.
        let (traj, exact) = sine(100.0, 2.0, std::f64::consts::FRAC_PI_2);
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        assert_eq!(table.qd[0][0], 0.0);
        assert!((table.qdd[0][0] - exact(0.0).2).abs() < 1e-4, "{}", table.qdd[0][0]);
    }

    #[test]
    fn ramps_splice_around_the_file_ticks() {
        let (traj, _) = sine(100.0, 1.0, 0.0);
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        let file = table.clone();
        let rest = JointState { q: table.q[0], ..Default::default() };
        let table = table.with_ramps(&[rest, rest], &[rest; 3]);
        assert_eq!((table.lead_in_ticks, table.lead_out_ticks), (2, 3));
        assert_eq!(table.ticks(), file.ticks() + 5);
        assert_eq!(table.file_ticks(), 2..file.ticks() + 2);
        assert_eq!(table.q[2..file.ticks() + 2], file.q[..]);
        assert_eq!(table.waypoint_ticks[0], 2);
        assert!((table.duration_s - (table.ticks() - 1) as f64 * table.dt).abs() < 1e-12);
        assert_eq!(table.file_start(), file.state(0));
    }

    #[test]
    fn coarse_or_resting_ends_stay_rest_to_rest() {
        // sin^4 and a dwell at both ends: the estimate cannot be told from rest.
        for traj in [wavy(21, 0.1), wavy(6, 0.2)] {
            assert!(boundary(&traj, true).is_none() && boundary(&traj, false).is_none());
        }
        let (moving, _) = sine(100.0, 1.0, 0.0);
        let b = boundary(&moving, true).expect("moving start");
        assert!((b.v[0] - 0.1 * 2.0 * std::f64::consts::PI * 0.2).abs() < 1e-8, "{:?}", b.v);
    }

    #[test]
    fn refuses_bad_rate_and_scale_and_is_deterministic() {
        let traj = wavy(4, 0.1);
        assert!(matches!(SetpointTable::build(&traj, 49.0, 1.0), Err(TimingError::Rate(_))));
        assert!(matches!(SetpointTable::build(&traj, 250.0, 0.0), Err(TimingError::SpeedScale(_))));
        assert!(matches!(SetpointTable::build(&traj, 250.0, 1.5), Err(TimingError::SpeedScale(_))));
        assert!(SetpointTable::build(&traj, f64::NAN, 1.0).is_err());
        let a = SetpointTable::build(&traj, 333.0, 0.7).expect("a");
        let b = SetpointTable::build(&traj, 333.0, 0.7).expect("b");
        assert_eq!(a, b);
    }
}
