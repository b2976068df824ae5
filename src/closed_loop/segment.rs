//! A correction as the tick will play it: from the offset in effect at its first tick, a Ruckig
//! move to the new joint offset, a hold, and a Ruckig move back to zero (the plan), sampled at
//! the control period; then every corrected setpoint it makes (plan plus offset) through the
//! preflight's rules (`hitl_trajectories::preflight::check_move`: joint limits and table,
//! velocity, acceleration, jerk, clearances, TCP speed) and the corridor. Only a segment that
//! passes is handed to the tick.
//!
//! Ruckig moves the offset from whatever state it is in (position, velocity, acceleration):
//! the offset is generated online, one segment per estimate, each continuing the one before.

use super::corridor::Corridor;
use crate::control::motion::MoveLimits;
use hitl_hal::{JointState, Joints, Pose, DOF};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::preflight::{check_move, MoveProfile};
use ruckig::{InputParameter, Result as RuckigResult, Ruckig, Trajectory};

/// Fraction of the lab's playback limits (velocity, acceleration, jerk) a correction's moves
/// use, on top of the plan's own motion; the sum is checked against the full limits.
pub const CORRECTION_LIMIT_FRACTION: f64 = 0.1;

/// The planned setpoints a segment corrects: the playback (from loop tick `first_tick`) and,
/// after it, its last setpoint held at rest (the settle).
#[derive(Debug, Clone)]
pub struct PlanTicks {
    pub first_tick: u64,
    pub playback: Vec<JointState>,
}

impl PlanTicks {
    /// The first loop tick after the playback.
    pub fn end_tick(&self) -> u64 {
        self.first_tick + self.playback.len() as u64
    }

    /// The planned setpoint at loop tick `k` (the approach's ticks are not the plan's: `None`).
    pub fn at(&self, k: u64) -> Option<JointState> {
        let i = usize::try_from(k.checked_sub(self.first_tick)?).ok()?;
        match self.playback.get(i) {
            Some(s) => Some(*s),
            None => self.playback.last().map(|s| JointState::rest(s.q)),
        }
    }
}

/// Everything a segment is planned and checked against.
#[derive(Debug, Clone)]
pub struct SegmentRules<'a> {
    pub plan: &'a PlanTicks,
    pub lab: &'a LabConfig,
    pub mount: Pose,
    pub corridor: Corridor,
    pub limits: MoveLimits,
    pub dt: f64,
    /// Ticks the new offset is held after its move (cut at the end of the playback).
    pub hold_ticks: u64,
    /// The return to the plan must be complete by this tick (within the settle).
    pub return_by_tick: u64,
    /// Most samples a segment may have (its buffers' size).
    pub capacity: usize,
}

impl<'a> SegmentRules<'a> {
    /// The lab's limits scaled by [`CORRECTION_LIMIT_FRACTION`].
    pub fn correction_limits(lab: &LabConfig) -> MoveLimits {
        let l = &lab.limits;
        let f = CORRECTION_LIMIT_FRACTION;
        MoveLimits {
            velocity: l.velocity_rad_s.map(|v| f * v),
            acceleration: l.acceleration_rad_s2.map(|v| f * v),
            jerk: l.jerk_rad_s3.map(|v| f * v),
        }
    }

    /// The offsets from `from_tick` (sample 0: `start`, the offset in effect there) moving to
    /// `goal` (or to zero when `goal` is `None`: back to the plan), checked. `Err` says why it
    /// was refused.
    pub fn plan(
        &self,
        from_tick: u64,
        start: &JointState,
        goal: Option<&Joints>,
    ) -> Result<Vec<JointState>, String> {
        if from_tick < self.plan.first_tick {
            return Err("a correction cannot start before the playback".into());
        }
        let zero = [0.0; DOF];
        let mut out = vec![*start];
        let to = goal.unwrap_or(&zero);
        out.extend(self.move_to(start, to)?);
        if goal.is_some() {
            // Held for `hold_ticks`; to the end of the playback when that is nearer than two.
            let moved_by = from_tick + out.len() as u64;
            let end = self.plan.end_tick();
            let natural = moved_by + self.hold_ticks;
            let hold_end = if natural + self.hold_ticks >= end { end.max(moved_by) } else { natural };
            out.extend(std::iter::repeat_n(JointState::rest(*to), (hold_end - moved_by) as usize));
            out.extend(self.move_to(&JointState::rest(*to), &zero)?);
        }
        if out.len() > self.capacity {
            return Err(format!("the correction needs {} ticks, more than {}", out.len(), self.capacity));
        }
        if from_tick + out.len() as u64 > self.return_by_tick {
            return Err("the return to the plan would not end within the settle".into());
        }
        self.check(from_tick, &out)?;
        Ok(out)
    }

    /// A Ruckig move of the offset from `from` (any state) to rest at `to`, sampled after `from`.
    fn move_to(&self, from: &JointState, to: &Joints) -> Result<Vec<JointState>, String> {
        let values = from.q.iter().chain(&from.qd).chain(&from.qdd).chain(to);
        if values.into_iter().any(|v| !v.is_finite()) {
            return Err("a correction is not finite".into());
        }
        let still = from.qd.iter().chain(&from.qdd).all(|v| *v == 0.0);
        if still && from.q.iter().zip(to).all(|(a, b)| (a - b).abs() < 1e-12) {
            return Ok(Vec::new());
        }
        let l = &self.limits;
        let mut input = InputParameter::new(DOF);
        input.current_position = from.q.to_vec();
        input.current_velocity = from.qd.to_vec();
        input.current_acceleration =
            (0..DOF).map(|j| from.qdd[j].clamp(-l.acceleration[j], l.acceleration[j])).collect();
        input.target_position = to.to_vec();
        input.max_velocity = l.velocity.to_vec();
        input.max_acceleration = l.acceleration.to_vec();
        input.max_jerk = l.jerk.to_vec();
        let mut ruckig = Ruckig::new_direct_and_offline(DOF);
        let mut traj = Trajectory::new_direct(DOF);
        match ruckig.calculate(&mut input, &mut traj) {
            RuckigResult::Working | RuckigResult::Finished => {}
            other => return Err(format!("Ruckig refused the correction: {other:?}")),
        }
        let duration = traj.get_duration();
        let steps = (duration / self.dt).ceil().max(1.0) as usize;
        let mut out = Vec::with_capacity(steps);
        for i in 1..=steps {
            let (p, v, a) = traj.at_time((i as f64 * self.dt).min(duration));
            let mut s = JointState::default();
            s.q.copy_from_slice(&p);
            s.qd.copy_from_slice(&v);
            s.qdd.copy_from_slice(&a);
            out.push(s);
        }
        if let Some(last) = out.last_mut() {
            *last = JointState::rest(*to);
        }
        Ok(out)
    }

    /// Every corrected setpoint through the preflight's rules and the corridor.
    fn check(&self, from_tick: u64, offsets: &[JointState]) -> Result<(), String> {
        let mut profile = MoveProfile {
            name: "closed-loop correction".into(),
            rate_hz: 1.0 / self.dt,
            via_ticks: vec![offsets.len().saturating_sub(1)],
            ..MoveProfile::default()
        };
        for (i, off) in offsets.iter().enumerate() {
            let k = from_tick + i as u64;
            let planned = self.plan.at(k).ok_or("a correction outside the plan")?;
            let q: Joints = std::array::from_fn(|j| planned.q[j] + off.q[j]);
            if !self.corridor.contains(&planned.q, &q, &self.mount) {
                return Err(format!(
                    "the corrected setpoint at tick {k} leaves the {:.1} mm corridor",
                    self.corridor.radius_m * 1e3
                ));
            }
            profile.q.push(q);
            profile.qd.push(std::array::from_fn(|j| planned.qd[j] + off.qd[j]));
            profile.qdd.push(std::array::from_fn(|j| planned.qdd[j] + off.qdd[j]));
        }
        let report = check_move(&profile, self.lab);
        if report.is_safe() {
            Ok(())
        } else {
            Err(report
                .violations
                .first()
                .map(|v| v.message.clone())
                .unwrap_or_else(|| "the preflight refused the correction".into()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rules<'a>(plan: &'a PlanTicks, lab: &'a LabConfig, corridor_m: f64) -> SegmentRules<'a> {
        SegmentRules {
            plan,
            lab,
            mount: lab.camera_mount(),
            corridor: Corridor::new(corridor_m).expect("valid"),
            limits: SegmentRules::correction_limits(lab),
            dt: 0.004,
            hold_ticks: 100,
            return_by_tick: plan.end_tick() + 250,
            capacity: 2000,
        }
    }

    #[test]
    fn a_segment_moves_holds_and_returns_to_the_plan_within_the_limits() {
        let lab = LabConfig::default();
        let plan = PlanTicks { first_tick: 10, playback: vec![JointState::rest(lab.arm.rest_q); 2000] };
        let r = rules(&plan, &lab, 0.003);
        let goal = [0.002, -0.001, 0.0, 0.001, 0.0, 0.0, 0.0];
        let s = r.plan(20, &JointState::default(), Some(&goal)).expect("passes");
        assert_eq!(s[0], JointState::default(), "starts from the offset in effect");
        assert_eq!(s.last().expect("samples").q, [0.0; DOF], "ends on the plan");
        assert!(s.iter().any(|o| o.q == goal), "holds the goal");
        let lim = SegmentRules::correction_limits(&lab);
        for w in s.windows(2) {
            for j in 0..DOF {
                assert!(w[1].qd[j].abs() <= lim.velocity[j] + 1e-9);
                assert!((w[1].q[j] - w[0].q[j]).abs() <= lim.velocity[j] * 0.004 + 1e-9);
            }
        }
    }

    #[test]
    fn a_segment_leaving_the_corridor_is_refused() {
        let lab = LabConfig::default();
        let plan = PlanTicks { first_tick: 0, playback: vec![JointState::rest(lab.arm.rest_q); 2000] };
        let r = rules(&plan, &lab, 0.001);
        let goal = [0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]; // ~1 cm at the camera
        let err = r.plan(5, &JointState::default(), Some(&goal)).expect_err("refused");
        assert!(err.contains("corridor"), "{err}");
        // Back to the plan from a moving offset is always a move of its own.
        let moving = JointState { q: [0.0005; DOF], qd: [0.01; DOF], qdd: [0.0; DOF] };
        let back = r.plan(5, &moving, None).expect("return passes");
        assert_eq!(back.last().expect("samples").q, [0.0; DOF]);
    }
}
