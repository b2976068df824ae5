//! The motion vocabulary shared by the planner, the loop and the recorder: a joint state (a
//! setpoint is a commanded one) and the phase of a run it belongs to.

use crate::arm::{Joints, DOF};

/// Position, velocity and acceleration of the joints: what a setpoint commands for one tick, and
/// what the timed trajectory holds for each tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointState {
    pub q: Joints,
    pub qd: Joints,
    pub qdd: Joints,
}

impl JointState {
    /// At rest at `q`.
    pub fn rest(q: Joints) -> Self {
        Self { q, qd: [0.0; DOF], qdd: [0.0; DOF] }
    }

    /// True when velocity and acceleration are zero on every joint.
    pub fn at_rest(&self) -> bool {
        self.qd.iter().chain(self.qdd.iter()).all(|x| *x == 0.0)
    }

    /// Where this state goes in `dt` seconds at constant acceleration: a bridge of a tick or
    /// two while a stop plan is being made.
    pub fn extrapolate(&self, dt: f64) -> Self {
        let mut next = *self;
        for j in 0..DOF {
            next.q[j] = self.q[j] + self.qd[j] * dt + 0.5 * self.qdd[j] * dt * dt;
            next.qd[j] = self.qd[j] + self.qdd[j] * dt;
        }
        next
    }
}

/// The phase of a run a setpoint belongs to. With the `serde` feature it serialises under the
/// names `/arm/setpoint` records (lowercase, `lead_in`, `lead_out`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum Phase {
    /// The slow, checked move from the arm's pose to the first waypoint.
    Approach,
    /// The trajectory itself.
    Playback,
    /// Holding the last waypoint until the arm has arrived. Recorded as [`Phase::Playback`]
    /// (see [`Phase::recorded`]): the hold belongs to the trajectory's end.
    Settle,
    /// A jerk-limited stop after a trip or an operator stop.
    Stop,
    /// From rest into the first waypoint's motion, for a trajectory that starts moving.
    #[cfg_attr(feature = "serde", serde(rename = "lead_in"))]
    LeadIn,
    /// From the last waypoint's motion to rest, for a trajectory that ends moving (and the hold
    /// at its end while the arm settles).
    #[cfg_attr(feature = "serde", serde(rename = "lead_out"))]
    LeadOut,
    /// After a completed run: the planned, checked move back to the lab's rest pose (and the hold
    /// there while the arm settles); `hitl park`'s move.
    Retreat,
}

impl Phase {
    /// The operator's name of the phase.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Approach => "approach",
            Phase::Playback => "playback",
            Phase::Settle => "settle",
            Phase::Stop => "stop",
            Phase::LeadIn => "lead-in",
            Phase::LeadOut => "lead-out",
            Phase::Retreat => "retreat",
        }
    }

    /// The phase as `/arm/setpoint` records it: the settle hold is part of playback there (the
    /// recording contract has no settle phase).
    pub fn recorded(self) -> Phase {
        match self {
            Phase::Settle => Phase::Playback,
            p => p,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extrapolate_follows_constant_acceleration() {
        let mut s = JointState::rest([0.0; DOF]);
        s.qd[2] = 1.0;
        s.qdd[2] = 2.0;
        let n = s.extrapolate(0.5);
        assert_eq!(n.q[2], 0.5 + 0.25);
        assert_eq!(n.qd[2], 2.0);
        assert!(!n.at_rest());
        assert!(JointState::rest([1.0; DOF]).at_rest());
    }

    #[test]
    fn settle_is_recorded_as_playback() {
        assert_eq!(Phase::Settle.recorded(), Phase::Playback);
        assert_eq!(Phase::Retreat.recorded(), Phase::Retreat);
    }
}
