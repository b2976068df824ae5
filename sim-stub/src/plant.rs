//! What the protocol server needs of a simulated arm: command it, step it, read it back.

use hitl_hal::Joints;

/// A collision the simulation detected between the arm (or its camera) and the scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Collision {
    /// The arm's body or geom that touches.
    pub arm_part: String,
    /// What it touches: an enclosure wall, the tripod, the target.
    pub other: String,
}

/// A simulated arm in servo mode. The server owns stepping in real time; the plant owns physics.
pub trait Plant: Send {
    /// Measured joint positions, radians.
    fn joints(&self) -> Joints;
    /// Measured joint velocities, rad/s.
    fn velocities(&self) -> Joints;
    /// Set the actuators' position targets (what a servo_j does on a real box).
    fn command(&mut self, q: &Joints);
    /// Place the arm at `q` at rest, targets included (start-up pose, tests).
    fn reset(&mut self, q: &Joints);
    /// Advance simulated time by `dt` seconds.
    fn advance(&mut self, dt: f64);
    /// Simulated time, seconds.
    fn time(&self) -> f64;
    /// The first collision between the arm and the enclosure, tripod or target, if any.
    fn collision(&self) -> Option<Collision>;
}
