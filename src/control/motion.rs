//! Jerk-limited moves planned with Ruckig (the official C++ library through the `ruckig` crate):
//! the approach from the arm's pose to the first waypoint, and stops from any moving state.
//!
//! Both are planned whole ("offline" in Ruckig's words) and sampled at the control period into
//! setpoints, so the tick only reads a table. Planning allocates: it runs before the loop
//! (approach) or on the stop planner's thread (stops), never in the tick.

use super::setpoint::Setpoint;
use hitl_hal::Joints;
use ruckig::{ControlInterface, InputParameter, Result as RuckigResult, Ruckig, Trajectory};

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
        Self { velocity: [velocity; 7], acceleration: [acceleration; 7], jerk: [jerk; 7] }
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
    out: &mut [Setpoint],
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
) -> Result<Vec<Setpoint>, MotionError> {
    if from.iter().chain(to.iter()).any(|v| !v.is_finite()) {
        return Err(MotionError::NotFinite);
    }
    if from.iter().zip(to).all(|(a, b)| (a - b).abs() < 1e-9) {
        return Ok(Vec::new());
    }
    let mut input = InputParameter::new(7);
    input.current_position = from.to_vec();
    input.target_position = to.to_vec();
    set_limits(&mut input, limits);
    let trajectory = calculate(&mut input)?;
    let mut out = vec![Setpoint::default(); (trajectory.get_duration() / dt).ceil() as usize + 1];
    let n = sample_into(&trajectory, dt, &mut out)?;
    out.truncate(n);
    if let Some(last) = out.last_mut() {
        *last = Setpoint::rest(*to);
    }
    Ok(out)
}

/// A jerk-limited stop from the moving state `from`: velocity and acceleration brought to zero
/// as fast as `limits` allow, sampled every `dt` into `out`. Returns how many samples it took.
pub fn plan_stop(
    from: &Setpoint,
    limits: &MoveLimits,
    dt: f64,
    out: &mut [Setpoint],
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
    input.current_acceleration = (0..7)
        .map(|j| from.qdd[j].clamp(-limits.acceleration[j], limits.acceleration[j]))
        .collect();
    input.target_velocity = vec![0.0; 7];
    input.target_acceleration = vec![0.0; 7];
    set_limits(&mut input, limits);
    let trajectory = calculate(&mut input)?;
    let n = sample_into(&trajectory, dt, out)?;
    // Come to rest exactly where the plan ends.
    out[n - 1].qd = [0.0; 7];
    out[n - 1].qdd = [0.0; 7];
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_move_ends_on_its_goal_within_limits() {
        let from = [0.0; 7];
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
    fn a_stop_brings_velocity_to_zero_smoothly() {
        let from =
            Setpoint { q: [0.0; 7], qd: [1.0, -0.5, 0.0, 0.2, 0.0, 0.0, 0.0], qdd: [0.0; 7] };
        let limits = MoveLimits::uniform(1.0, 4.0, 60.0);
        let mut out = vec![Setpoint::default(); 1000];
        let n = plan_stop(&from, &limits, 0.004, &mut out).expect("stop");
        assert_eq!(out[n - 1].qd, [0.0; 7]);
        // Joint 1 keeps moving forward while it brakes, and stops in well under a second.
        assert!(out[n - 1].q[0] > 0.0 && out[n - 1].q[0] < 0.5, "{}", out[n - 1].q[0]);
        assert!((n as f64) * 0.004 < 0.6);
        for w in out[..n].windows(2) {
            for j in 0..7 {
                let dqd = (w[1].qd[j] - w[0].qd[j]).abs();
                assert!(dqd <= 4.0 * 0.004 + 1e-6, "acceleration limit");
            }
        }
    }

    #[test]
    fn non_finite_inputs_are_refused() {
        let limits = MoveLimits::uniform(1.0, 4.0, 60.0);
        let mut bad = [0.0; 7];
        bad[2] = f64::NAN;
        assert_eq!(plan_move(&bad, &[0.0; 7], &limits, 0.004), Err(MotionError::NotFinite));
    }
}
