//! A correction as the tick will play it. The camera correction (lab metres, base frame) moves
//! with Ruckig from its state at the segment's first tick (position, velocity, acceleration: the
//! correction is generated online, each segment continuing the one in effect) to the new one,
//! holds, and moves back to zero (the plan); at every tick the joint offset that displaces the
//! camera of the planned setpoint by that correction, orientation kept, is solved on the xArm7's
//! kinematics. Then every corrected setpoint (plan plus offset) goes through the preflight's
//! rules (`hitl_trajectories::preflight::check_move`: joint limits and table, velocity,
//! acceleration, jerk, clearances, TCP speed) and the corridor. Only a segment that passes is
//! handed to the tick.

use super::corridor::Corridor;
use super::guidance::joint_offset;
use hitl_hal::{JointState, Joints, Pose, DOF};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::preflight::{check_move, MoveProfile};
use nalgebra::Vector3;
use ruckig::{InputParameter, Result as RuckigResult, Ruckig, Trajectory};

/// Limits of the camera correction's moves (lab): 10 mm/s, 50 mm/s^2, 500 mm/s^3 per axis. The
/// plan's own motion comes on top; the sum is checked against the lab's full limits.
pub const CORRECTION_SPEED_M_S: f64 = 0.010;
pub const CORRECTION_ACCEL_M_S2: f64 = 0.050;
pub const CORRECTION_JERK_M_S3: f64 = 0.500;

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

/// The camera correction's state at one tick (lab metres, base frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CartState {
    pub p: Vector3<f64>,
    pub v: Vector3<f64>,
    pub a: Vector3<f64>,
}

/// A planned correction: per tick from its first, the camera correction and the joint offset.
#[derive(Debug, Clone, Default)]
pub struct Planned {
    pub cart: Vec<CartState>,
    pub offsets: Vec<JointState>,
}

/// Everything a segment is planned and checked against.
#[derive(Debug, Clone)]
pub struct SegmentRules<'a> {
    pub plan: &'a PlanTicks,
    pub lab: &'a LabConfig,
    pub mount: Pose,
    pub corridor: Corridor,
    pub dt: f64,
    /// Ticks the new correction is held after its move (to the end of the playback when that is
    /// nearer than two holds).
    pub hold_ticks: u64,
    /// The return to the plan must be complete by this tick (within the settle).
    pub return_by_tick: u64,
    /// Most samples a segment may have (its buffers' size).
    pub capacity: usize,
}

impl SegmentRules<'_> {
    /// The correction from `from_tick`, starting from `start` (the correction in effect there,
    /// whose joint offset is `start_offset`), moving to `goal` (or back to zero when `None`),
    /// checked. `Err` says why it was refused.
    pub fn plan(
        &self,
        from_tick: u64,
        start: &CartState,
        start_offset: &JointState,
        goal: Option<&Vector3<f64>>,
    ) -> Result<Planned, String> {
        if from_tick < self.plan.first_tick {
            return Err("a correction cannot start before the playback".into());
        }
        let to = goal.copied().unwrap_or_else(Vector3::zeros);
        if to.norm() > self.corridor.radius_m + 1e-9 {
            return Err("the correction is wider than the corridor".into());
        }
        let mut cart = vec![*start];
        cart.extend(self.move_to(start, &to)?);
        if goal.is_some() {
            let moved_by = from_tick + cart.len() as u64;
            let end = self.plan.end_tick();
            let natural = moved_by + self.hold_ticks;
            let hold_end =
                if natural + self.hold_ticks >= end { end.max(moved_by) } else { natural };
            let rest = CartState { p: to, ..CartState::default() };
            cart.extend(std::iter::repeat_n(rest, (hold_end - moved_by) as usize));
            cart.extend(self.move_to(&rest, &Vector3::zeros())?);
        }
        if cart.len() > self.capacity {
            return Err(format!(
                "the correction needs {} ticks, more than {}",
                cart.len(),
                self.capacity
            ));
        }
        if from_tick + cart.len() as u64 > self.return_by_tick {
            return Err("the return to the plan would not end within the settle".into());
        }
        let offsets = self.joint_offsets(from_tick, &cart, start_offset)?;
        self.check(from_tick, &offsets)?;
        Ok(Planned { cart, offsets })
    }

    /// A Ruckig move of the correction from `from` (any state) to rest at `to`, sampled after
    /// `from`.
    fn move_to(&self, from: &CartState, to: &Vector3<f64>) -> Result<Vec<CartState>, String> {
        let values = from.p.iter().chain(&from.v).chain(&from.a).chain(to);
        if values.into_iter().any(|v| !v.is_finite()) {
            return Err("a correction is not finite".into());
        }
        if from.v == Vector3::zeros() && from.a == Vector3::zeros() && (from.p - to).norm() < 1e-12
        {
            return Ok(Vec::new());
        }
        let mut input = InputParameter::new(3);
        input.current_position = from.p.as_slice().to_vec();
        input.current_velocity = from.v.as_slice().to_vec();
        input.current_acceleration =
            from.a.iter().map(|a| a.clamp(-CORRECTION_ACCEL_M_S2, CORRECTION_ACCEL_M_S2)).collect();
        input.target_position = to.as_slice().to_vec();
        input.max_velocity = vec![CORRECTION_SPEED_M_S; 3];
        input.max_acceleration = vec![CORRECTION_ACCEL_M_S2; 3];
        input.max_jerk = vec![CORRECTION_JERK_M_S3; 3];
        let mut ruckig = Ruckig::new_direct_and_offline(3);
        let mut traj = Trajectory::new_direct(3);
        match ruckig.calculate(&mut input, &mut traj) {
            RuckigResult::Working | RuckigResult::Finished => {}
            other => return Err(format!("Ruckig refused the correction: {other:?}")),
        }
        let duration = traj.get_duration();
        let steps = (duration / self.dt).ceil().max(1.0) as usize;
        let v3 = |x: &[f64]| Vector3::new(x[0], x[1], x[2]);
        let mut out: Vec<CartState> = (1..=steps)
            .map(|i| {
                let (p, v, a) = traj.at_time((i as f64 * self.dt).min(duration));
                CartState { p: v3(&p), v: v3(&v), a: v3(&a) }
            })
            .collect();
        if let Some(last) = out.last_mut() {
            *last = CartState { p: *to, ..CartState::default() };
        }
        Ok(out)
    }

    /// The joint offset of every tick (sample 0: `start`, the offset in effect), its velocity and
    /// acceleration by backward differences.
    fn joint_offsets(
        &self,
        from_tick: u64,
        cart: &[CartState],
        start: &JointState,
    ) -> Result<Vec<JointState>, String> {
        let mut out = Vec::with_capacity(cart.len());
        out.push(*start);
        for (i, c) in cart.iter().enumerate().skip(1) {
            let k = from_tick + i as u64;
            let planned = self.plan.at(k).ok_or("a correction outside the plan")?;
            let prev = out[i - 1];
            let q = if c.p == Vector3::zeros() {
                [0.0; DOF]
            } else {
                // From the plan itself (not the previous tick's offset): the offset is then a
                // function of the planned joints and the correction alone, smooth along the
                // plan and zero with the correction (no drift along the arm's self-motion).
                joint_offset(&planned.q, &c.p, &self.mount, &[0.0; DOF]).ok_or_else(|| {
                    format!("no joint offset moves the camera by the correction at tick {k}")
                })?
            };
            let qd: Joints = std::array::from_fn(|j| (q[j] - prev.q[j]) / self.dt);
            let qdd: Joints = std::array::from_fn(|j| (qd[j] - prev.qd[j]) / self.dt);
            out.push(JointState { q, qd, qdd });
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
    use hitl_trajectories::kinematics::camera_pose;

    fn rules<'a>(plan: &'a PlanTicks, lab: &'a LabConfig, corridor_m: f64) -> SegmentRules<'a> {
        SegmentRules {
            plan,
            lab,
            mount: lab.camera_mount(),
            corridor: Corridor::new(corridor_m).expect("valid"),
            dt: 0.004,
            hold_ticks: 100,
            return_by_tick: plan.end_tick() + 250,
            capacity: 2000,
        }
    }

    #[test]
    fn a_segment_moves_the_camera_holds_and_returns_to_the_plan() {
        let lab = LabConfig::default();
        let plan =
            PlanTicks { first_tick: 10, playback: vec![JointState::rest(lab.arm.rest_q); 2000] };
        let r = rules(&plan, &lab, 0.003);
        let goal = Vector3::new(0.002, -0.001, 0.001);
        let s =
            r.plan(20, &CartState::default(), &JointState::default(), Some(&goal)).expect("passes");
        assert_eq!(s.offsets[0], JointState::default(), "starts from the offset in effect");
        assert_eq!(s.offsets.last().expect("samples").q, [0.0; DOF], "ends on the plan");
        let mount = lab.camera_mount();
        let at = |q: &Joints| camera_pose(q, &mount).translation.vector;
        let held = s.cart.iter().position(|c| c.p == goal).expect("holds the goal");
        let q: Joints = std::array::from_fn(|j| lab.arm.rest_q[j] + s.offsets[held].q[j]);
        assert!((at(&q) - at(&lab.arm.rest_q) - goal).norm() < 1e-6, "the camera moved by it");
        for c in &s.cart {
            assert!(c.v.amax() <= CORRECTION_SPEED_M_S + 1e-9);
        }
    }

    #[test]
    fn a_correction_wider_than_the_corridor_is_refused_and_a_return_always_planned() {
        let lab = LabConfig::default();
        let plan =
            PlanTicks { first_tick: 0, playback: vec![JointState::rest(lab.arm.rest_q); 2000] };
        let r = rules(&plan, &lab, 0.001);
        let wide = Vector3::new(0.002, 0.0, 0.0);
        let err = r.plan(5, &CartState::default(), &JointState::default(), Some(&wide));
        assert!(err.expect_err("refused").contains("corridor"));
        // Back to the plan from a correction in effect (held: the joint offset given with it
        // has no velocity either).
        let moving = CartState { p: Vector3::new(0.0008, 0.0, 0.0), ..CartState::default() };
        let dq =
            joint_offset(&lab.arm.rest_q, &moving.p, &lab.camera_mount(), &[0.0; DOF]).expect("ik");
        let back = r
            .plan(5, &moving, &JointState { q: dq, ..JointState::default() }, None)
            .expect("return passes");
        assert_eq!(back.offsets.last().expect("samples").q, [0.0; DOF]);
        assert!(back.cart.iter().all(|c| c.p.norm() <= 0.001 + 1e-9), "the overshoot stays inside");
    }
}
