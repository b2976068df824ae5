//! A commanded joint state, and the phase of the run it belongs to.

use hitl_hal::{Joints, DOF};

/// Position, velocity and acceleration commanded for one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Setpoint {
    pub q: Joints,
    pub qd: Joints,
    pub qdd: Joints,
}

impl Setpoint {
    /// At rest at `q`.
    pub fn rest(q: Joints) -> Self {
        Self { q, qd: [0.0; DOF], qdd: [0.0; DOF] }
    }

    /// Where this setpoint goes in `dt` seconds at constant acceleration: a bridge of a tick or
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

/// The phase a setpoint belongs to, as recorded on `/arm/setpoint`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The slow, checked move from the arm's pose to the first waypoint.
    Approach,
    /// The trajectory itself.
    Playback,
    /// Holding the last waypoint until the arm has arrived.
    Settle,
    /// A jerk-limited stop after a trip or an operator stop.
    Stop,
    /// From rest into the first waypoint's motion, for a trajectory that starts moving.
    LeadIn,
    /// From the last waypoint's motion to rest, for a trajectory that ends moving (and the hold
    /// at its end while the arm settles).
    LeadOut,
    /// After a completed run: the planned, checked move back to the lab's rest pose (and the hold
    /// there while the arm settles); `hitl park`'s move.
    Retreat,
}

impl Phase {
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
}
