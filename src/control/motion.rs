//! Jerk-limited moves planned with Ruckig (the official C++ library through the `ruckig` crate):
//! the approach and the retreat along a planned path of straight joint-space legs
//! ([`plan_path`]; the path itself is `hitl_trajectories::path`'s), stops from any moving state,
//! and the lead-in and lead-out of a trajectory that starts or ends moving ([`add_ramps`]).
//!
//! Both are planned whole ("offline" in Ruckig's words) and sampled at the control period into
//! setpoints, so the tick only reads a table. Planning allocates: it runs before the loop
//! (approach) or on the stop planner's thread (stops), never in the tick.

use hitl_hal::JointState;
use hitl_hal::{Joints, DOF};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::SetpointTable;
use ruckig::{
    ControlInterface, InputParameter, Result as RuckigResult, Ruckig, Synchronization, Trajectory,
};

/// Per-joint kinematic limits for a planned move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveLimits {
    pub velocity: Joints,
    pub acceleration: Joints,
    pub jerk: Joints,
}

impl MoveLimits {
    /// The same limits on every joint.
    pub fn uniform(velocity: f64, acceleration: f64, jerk: f64) -> Self {
        Self { velocity: [velocity; DOF], acceleration: [acceleration; DOF], jerk: [jerk; DOF] }
    }
}

/// Why Ruckig could not plan a move.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionError {
    #[error("Ruckig refused the move: {0}")]
    Ruckig(String),
    #[error("the move is longer than the {0} setpoints allowed for it")]
    TooLong(usize),
    #[error("the move's start or goal is not finite")]
    NotFinite,
}

fn calculate(input: &mut InputParameter) -> Result<Trajectory, MotionError> {
    let mut ruckig = Ruckig::new_direct_and_offline(7);
    let mut trajectory = Trajectory::new_direct(7);
    match ruckig.calculate(input, &mut trajectory) {
        RuckigResult::Working | RuckigResult::Finished => Ok(trajectory),
        other => Err(MotionError::Ruckig(format!("{other:?}"))),
    }
}

fn set_limits(input: &mut InputParameter, limits: &MoveLimits) {
    input.max_velocity = limits.velocity.to_vec();
    input.max_acceleration = limits.acceleration.to_vec();
    input.max_jerk = limits.jerk.to_vec();
}

/// Sample `trajectory` every `dt` seconds after its start, ending exactly on its end.
fn sample_into(
    trajectory: &Trajectory,
    dt: f64,
    out: &mut [JointState],
) -> Result<usize, MotionError> {
    let duration = trajectory.get_duration();
    let steps = (duration / dt).ceil().max(1.0) as usize;
    if steps > out.len() {
        return Err(MotionError::TooLong(out.len()));
    }
    for (i, slot) in out.iter_mut().take(steps).enumerate() {
        let t = ((i + 1) as f64 * dt).min(duration);
        let (p, v, a) = trajectory.at_time(t);
        slot.q.copy_from_slice(&p);
        slot.qd.copy_from_slice(&v);
        slot.qdd.copy_from_slice(&a);
    }
    Ok(steps)
}

/// A rest-to-rest move from `from` to `to`, sampled every `dt` (the start itself excluded, the
/// goal included). Empty when the arm is already there.
pub fn plan_move(
    from: &Joints,
    to: &Joints,
    limits: &MoveLimits,
    dt: f64,
) -> Result<Vec<JointState>, MotionError> {
    plan_move_synchronized(from, to, limits, dt, Synchronization::Time)
}

/// A rest-to-rest move along the straight line from `from` to `to` in joint space (Ruckig's
/// phase synchronisation: every joint covers the same fraction of its way at every instant),
/// sampled as [`plan_move`].
pub fn plan_straight_move(
    from: &Joints,
    to: &Joints,
    limits: &MoveLimits,
    dt: f64,
) -> Result<Vec<JointState>, MotionError> {
    plan_move_synchronized(from, to, limits, dt, Synchronization::Phase)
}

/// A path of straight joint-space legs through `waypoints` (the first is where the arm rests),
/// each leg a rest-to-rest [`plan_straight_move`]: the setpoints after the start, and the index
/// (1-based, as ticks after the start) of the setpoint that ends each leg.
pub fn plan_path(
    waypoints: &[Joints],
    limits: &MoveLimits,
    dt: f64,
) -> Result<(Vec<JointState>, Vec<usize>), MotionError> {
    let mut out = Vec::new();
    let mut ends = Vec::new();
    for leg in waypoints.windows(2) {
        out.extend(plan_straight_move(&leg[0], &leg[1], limits, dt)?);
        ends.push(out.len());
    }
    Ok((out, ends))
}

fn plan_move_synchronized(
    from: &Joints,
    to: &Joints,
    limits: &MoveLimits,
    dt: f64,
    synchronization: Synchronization,
) -> Result<Vec<JointState>, MotionError> {
    if from.iter().chain(to.iter()).any(|v| !v.is_finite()) {
        return Err(MotionError::NotFinite);
    }
    if from.iter().zip(to).all(|(a, b)| (a - b).abs() < 1e-9) {
        return Ok(Vec::new());
    }
    let mut input = InputParameter::new(7);
    input.synchronization = synchronization;
    input.current_position = from.to_vec();
    input.target_position = to.to_vec();
    set_limits(&mut input, limits);
    let trajectory = calculate(&mut input)?;
    let mut out = vec![JointState::default(); (trajectory.get_duration() / dt).ceil() as usize + 1];
    let n = sample_into(&trajectory, dt, &mut out)?;
    out.truncate(n);
    if let Some(last) = out.last_mut() {
        *last = JointState::rest(*to);
    }
    Ok(out)
}

/// A jerk-limited stop from the moving state `from`: velocity and acceleration brought to zero
/// as fast as `limits` allow, sampled every `dt` into `out`. Returns how many samples it took.
pub fn plan_stop(
    from: &JointState,
    limits: &MoveLimits,
    dt: f64,
    out: &mut [JointState],
) -> Result<usize, MotionError> {
    let values = from.q.iter().chain(from.qd.iter()).chain(from.qdd.iter());
    if values.into_iter().any(|v| !v.is_finite()) {
        return Err(MotionError::NotFinite);
    }
    let mut input = InputParameter::new(7);
    input.control_interface = ControlInterface::Velocity;
    input.current_position = from.q.to_vec();
    input.current_velocity = from.qd.to_vec();
    // Ruckig needs the current acceleration within its limit.
    input.current_acceleration = (0..DOF)
        .map(|j| from.qdd[j].clamp(-limits.acceleration[j], limits.acceleration[j]))
        .collect();
    input.target_velocity = vec![0.0; DOF];
    input.target_acceleration = vec![0.0; DOF];
    set_limits(&mut input, limits);
    let trajectory = calculate(&mut input)?;
    let n = sample_into(&trajectory, dt, out)?;
    // Come to rest exactly where the plan ends.
    out[n - 1].qd = [0.0; DOF];
    out[n - 1].qdd = [0.0; DOF];
    Ok(n)
}

/// Fraction of the lab's playback limits (velocity, acceleration, jerk) a lead-in or lead-out
/// plans with, so that sampling at the tick never brings a ramp to a limit.
pub const RAMP_LIMIT_FRACTION: f64 = 0.8;

/// The limits a ramp into or out of `state` plans with at tick period `dt`:
/// [`RAMP_LIMIT_FRACTION`] of the lab's playback limits (the velocity also of the per-tick step
/// limit), raised to the state's own velocity and acceleration where those are higher (Ruckig
/// needs the state inside its limits; a state beyond the lab's limits is the file's own
/// violation, which the preflight names at the file's tick).
fn ramp_limits(state: &JointState, lab: &LabConfig, dt: f64) -> MoveLimits {
    let l = &lab.limits;
    MoveLimits {
        velocity: std::array::from_fn(|j| {
            (RAMP_LIMIT_FRACTION * l.velocity_rad_s[j].min(l.max_step_rad / dt))
                .max(state.qd[j].abs() * (1.0 + 1e-9))
        }),
        acceleration: std::array::from_fn(|j| {
            (RAMP_LIMIT_FRACTION * l.acceleration_rad_s2[j]).max(state.qdd[j].abs() * (1.0 + 1e-6))
        }),
        jerk: l.jerk_rad_s3.map(|x| RAMP_LIMIT_FRACTION * x),
    }
}

/// The time-optimal jerk-limited way from the moving `state` to rest (velocity interface: the
/// position is free), as a Ruckig trajectory.
fn to_rest(state: &JointState, limits: &MoveLimits) -> Result<Trajectory, MotionError> {
    let values = state.q.iter().chain(state.qd.iter()).chain(state.qdd.iter());
    if values.into_iter().any(|v| !v.is_finite()) {
        return Err(MotionError::NotFinite);
    }
    let mut input = InputParameter::new(7);
    input.control_interface = ControlInterface::Velocity;
    input.current_position = state.q.to_vec();
    input.current_velocity = state.qd.to_vec();
    input.current_acceleration = state.qdd.to_vec();
    input.target_velocity = vec![0.0; DOF];
    input.target_acceleration = vec![0.0; DOF];
    set_limits(&mut input, limits);
    calculate(&mut input)
}

/// Most ticks a ramp may take (a minute at 1 kHz); a longer one is refused.
const MAX_RAMP_TICKS: usize = 60_000;

/// Samples of `trajectory` at `times` (each clamped to its duration).
fn sample_at(trajectory: &Trajectory, times: impl Iterator<Item = f64>) -> Vec<JointState> {
    let duration = trajectory.get_duration();
    times
        .map(|t| {
            let (p, v, a) = trajectory.at_time(t.clamp(0.0, duration));
            let mut s = JointState::default();
            s.q.copy_from_slice(&p);
            s.qd.copy_from_slice(&v);
            s.qdd.copy_from_slice(&a);
            s
        })
        .collect()
}

/// A lead-in: from rest to exactly `to` (position, velocity, acceleration), sampled every `dt`,
/// its first sample at rest and its last one tick before `to`. Empty when `to` is at rest.
///
/// Planned backwards: the time-reversed motion (velocity negated, acceleration kept) is a
/// jerk-limited stop from `to`, and a stop never turns back, so the lead-in runs straight into
/// the file's motion from the nearest rest that can reach it within `limits`.
pub fn plan_lead_in(
    to: &JointState,
    limits: &MoveLimits,
    dt: f64,
) -> Result<Vec<JointState>, MotionError> {
    if to.at_rest() {
        return Ok(Vec::new());
    }
    let reversed = JointState { q: to.q, qd: to.qd.map(|v| -v), qdd: to.qdd };
    let stop = to_rest(&reversed, limits)?;
    let duration = stop.get_duration();
    let steps = (duration / dt).ceil().max(1.0) as usize;
    if steps > MAX_RAMP_TICKS {
        return Err(MotionError::TooLong(MAX_RAMP_TICKS));
    }
    let mut out = sample_at(&stop, (1..=steps).rev().map(|m| m as f64 * dt));
    for s in &mut out {
        s.qd = s.qd.map(|v| -v);
    }
    // Start exactly at rest.
    out[0].qd = [0.0; DOF];
    out[0].qdd = [0.0; DOF];
    Ok(out)
}

/// A lead-out: from `from` (position, velocity, acceleration) to rest, sampled every `dt` after
/// it, its last sample exactly at rest. Empty when `from` is at rest.
pub fn plan_lead_out(
    from: &JointState,
    limits: &MoveLimits,
    dt: f64,
) -> Result<Vec<JointState>, MotionError> {
    if from.at_rest() {
        return Ok(Vec::new());
    }
    let stop = to_rest(from, limits)?;
    let steps = (stop.get_duration() / dt).ceil().max(1.0) as usize;
    if steps > MAX_RAMP_TICKS {
        return Err(MotionError::TooLong(MAX_RAMP_TICKS));
    }
    let mut out = sample_at(&stop, (1..=steps).map(|m| m as f64 * dt));
    let last = out.len() - 1;
    out[last].qd = [0.0; DOF];
    out[last].qdd = [0.0; DOF];
    Ok(out)
}

/// Give `table` its lead-in and lead-out where the file starts or ends moving, planned within
/// [`RAMP_LIMIT_FRACTION`] of the lab's playback limits; a table at rest at both ends comes back
/// unchanged. The result goes through the preflight like any table.
pub fn add_ramps(table: SetpointTable, lab: &LabConfig) -> Result<SetpointTable, MotionError> {
    let (start, end) = (table.file_start(), table.file_end());
    let dt = table.dt;
    let lead_in = plan_lead_in(&start, &ramp_limits(&start, lab, dt), dt)?;
    let lead_out = plan_lead_out(&end, &ramp_limits(&end, lab, dt), dt)?;
    Ok(table.with_ramps(&lead_in, &lead_out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lead_in_arrives_on_the_moving_state_and_a_lead_out_leaves_it_to_rest() {
        let state = JointState {
            q: [0.1, -0.4, 0.0, 1.4, 0.0, 1.5, 0.0],
            qd: [0.126, 0.0, -0.3, 0.0, 0.0, 0.05, 0.0],
            qdd: [0.0, 0.5, 0.2, 0.0, 0.0, 0.0, -0.1],
        };
        let limits = MoveLimits::uniform(0.8, 3.2, 48.0);
        let dt = 0.004;
        let lead_in = plan_lead_in(&state, &limits, dt).expect("lead-in");
        let lead_out = plan_lead_out(&state, &limits, dt).expect("lead-out");
        assert!(!lead_in.is_empty() && !lead_out.is_empty());
        assert!(lead_in[0].at_rest() && lead_out[lead_out.len() - 1].at_rest());
        // One tick of constant jerk at most separates each ramp from the state it meets.
        let within = |s: &JointState, t: f64| {
            (0..DOF).all(|j| {
                let p = s.q[j] + s.qd[j] * t + 0.5 * s.qdd[j] * t * t;
                (p - state.q[j]).abs() <= 48.0 * dt.powi(3) / 6.0 * 1.01 + 1e-12
                    && (s.qd[j] + s.qdd[j] * t - state.qd[j]).abs()
                        <= 0.5 * 48.0 * dt * dt * 1.01 + 1e-12
                    && (s.qdd[j] - state.qdd[j]).abs() <= 48.0 * dt * 1.0001 + 1e-12
            })
        };
        assert!(within(&lead_in[lead_in.len() - 1], dt), "{:?}", lead_in[lead_in.len() - 1]);
        assert!(within(&lead_out[0], -dt), "{:?}", lead_out[0]);
        // Within the limits on every sample, and continuous in acceleration.
        for ramp in [&lead_in, &lead_out] {
            for w in ramp.windows(2) {
                for j in 0..DOF {
                    assert!(w[1].qd[j].abs() <= 0.8 + 1e-9);
                    assert!(w[1].qdd[j].abs() <= 3.2 + 1e-9);
                    assert!((w[1].qdd[j] - w[0].qdd[j]).abs() <= 48.0 * dt * 1.0001 + 1e-12);
                }
            }
        }
        assert!(plan_lead_in(&JointState::default(), &limits, dt).expect("rest").is_empty());
    }

    #[test]
    fn a_move_ends_on_its_goal_within_limits() {
        let from = [0.0; DOF];
        let to = [0.3, -0.2, 0.0, 0.5, 0.0, 0.1, 0.0];
        let limits = MoveLimits::uniform(0.3, 0.8, 8.0);
        let path = plan_move(&from, &to, &limits, 0.004).expect("plan");
        assert_eq!(path.last().expect("samples").q, to);
        let mut prev = from;
        for sp in &path {
            for (j, p) in prev.iter().enumerate() {
                assert!(sp.qd[j].abs() <= 0.3 + 1e-6, "velocity {}", sp.qd[j]);
                assert!((sp.q[j] - p).abs() <= 0.3 * 0.004 + 1e-6);
            }
            prev = sp.q;
        }
        // 0.5 rad at 0.3 rad/s takes at least 1.67 s.
        assert!(path.len() as f64 * 0.004 > 1.67);
        assert!(plan_move(&to, &to, &limits, 0.004).expect("plan").is_empty());
    }

    #[test]
    fn a_path_follows_straight_legs_through_its_waypoints() {
        let a = [0.0; DOF];
        let b = [0.4, -0.2, 0.0, 0.5, 0.0, 0.1, 0.0];
        let c = [0.4, 0.1, 0.3, 0.5, 0.0, 0.1, -0.2];
        let limits = MoveLimits::uniform(0.3, 0.8, 8.0);
        let (path, ends) = plan_path(&[a, b, c], &limits, 0.004).expect("plan");
        assert_eq!(ends.len(), 2);
        assert_eq!(path[ends[0] - 1], JointState::rest(b));
        assert_eq!(path[ends[1] - 1], JointState::rest(c));
        assert_eq!(ends[1], path.len());
        // On the line a-b every sample is a + s (b - a) for one s.
        for sp in &path[..ends[0]] {
            let s = sp.q[0] / b[0];
            for j in 0..DOF {
                assert!((sp.q[j] - (a[j] + s * (b[j] - a[j]))).abs() < 1e-6, "{:?}", sp.q);
            }
        }
    }

    #[test]
    fn a_stop_brings_velocity_to_zero_smoothly() {
        let from =
            JointState { q: [0.0; DOF], qd: [1.0, -0.5, 0.0, 0.2, 0.0, 0.0, 0.0], qdd: [0.0; DOF] };
        let limits = MoveLimits::uniform(1.0, 4.0, 60.0);
        let mut out = vec![JointState::default(); 1000];
        let n = plan_stop(&from, &limits, 0.004, &mut out).expect("stop");
        assert_eq!(out[n - 1].qd, [0.0; DOF]);
        // Joint 1 keeps moving forward while it brakes, and stops in well under a second.
        assert!(out[n - 1].q[0] > 0.0 && out[n - 1].q[0] < 0.5, "{}", out[n - 1].q[0]);
        assert!((n as f64) * 0.004 < 0.6);
        for w in out[..n].windows(2) {
            for j in 0..DOF {
                let dqd = (w[1].qd[j] - w[0].qd[j]).abs();
                assert!(dqd <= 4.0 * 0.004 + 1e-6, "acceleration limit");
            }
        }
    }

    #[test]
    fn non_finite_inputs_are_refused() {
        let limits = MoveLimits::uniform(1.0, 4.0, 60.0);
        let mut bad = [0.0; DOF];
        bad[2] = f64::NAN;
        assert_eq!(plan_move(&bad, &[0.0; DOF], &limits, 0.004), Err(MotionError::NotFinite));
    }
}
