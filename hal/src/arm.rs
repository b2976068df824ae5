//! The arm: a command side streamed by the tick, and a report side read by its own thread.

use crate::error::ErrorType;

/// Joints of the xArm7.
pub const DOF: usize = 7;

/// Joint positions in radians, joint 1 first.
pub type Joints = [f64; DOF];

/// One report from the arm: its measured joints and its state machine, stamped on receipt.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmState {
    /// Host monotonic time at which the report was received, nanoseconds.
    pub received_ns: u64,
    /// Measured joint positions, radians.
    pub q: Joints,
    /// Arm state as the box reports it (1 moving, 2 sleeping/ready, 3 paused, 4 stopped, 5 ...).
    pub state: u8,
    /// Arm mode (0 position, 1 servo, ...).
    pub mode: u8,
    /// Controller error code, 0 when none.
    pub error_code: u8,
    /// Controller warning code, 0 when none.
    pub warn_code: u8,
    /// Report sequence number as counted by the reader (for the watchdog).
    pub seq: u64,
}

/// The command side of an arm in servo mode.
///
/// `servo_joint` is called from the real-time tick: implementations must not allocate and must
/// bound the time they block (a socket write with a send timeout).
pub trait Arm: ErrorType {
    /// Clear errors and warnings, enable the motors, enter servo mode (1) and the ready state (0).
    fn enable_servo(&mut self) -> Result<(), Self::Error>;
    /// Stream one servo setpoint. Hot path: no allocation, bounded blocking.
    fn servo_joint(&mut self, q: &Joints) -> Result<(), Self::Error>;
    /// Stop motion at once (the box's stop state). Used when no controlled motion is possible.
    fn stop(&mut self) -> Result<(), Self::Error>;
    /// Ask the arm for its joint positions (a request/reply, not for the hot path).
    fn joint_positions(&mut self) -> Result<Joints, Self::Error>;
    /// Ask the arm for its (error, warning) codes.
    fn codes(&mut self) -> Result<(u8, u8), Self::Error>;
}

/// The report side of an arm: a stream of [`ArmState`]s, read on a thread of its own.
pub trait ArmReports: ErrorType {
    /// Block until the next report arrives (or the reader's timeout passes).
    fn next_report(&mut self) -> Result<ArmState, Self::Error>;
}

impl<T: Arm + ?Sized> Arm for &mut T {
    fn enable_servo(&mut self) -> Result<(), Self::Error> {
        T::enable_servo(self)
    }
    fn servo_joint(&mut self, q: &Joints) -> Result<(), Self::Error> {
        T::servo_joint(self, q)
    }
    fn stop(&mut self) -> Result<(), Self::Error> {
        T::stop(self)
    }
    fn joint_positions(&mut self) -> Result<Joints, Self::Error> {
        T::joint_positions(self)
    }
    fn codes(&mut self) -> Result<(u8, u8), Self::Error> {
        T::codes(self)
    }
}

impl<T: ArmReports + ?Sized> ArmReports for &mut T {
    fn next_report(&mut self) -> Result<ArmState, Self::Error> {
        T::next_report(self)
    }
}

impl<T: Arm + ?Sized> Arm for Box<T> {
    fn enable_servo(&mut self) -> Result<(), Self::Error> {
        T::enable_servo(self)
    }
    fn servo_joint(&mut self, q: &Joints) -> Result<(), Self::Error> {
        T::servo_joint(self, q)
    }
    fn stop(&mut self) -> Result<(), Self::Error> {
        T::stop(self)
    }
    fn joint_positions(&mut self) -> Result<Joints, Self::Error> {
        T::joint_positions(self)
    }
    fn codes(&mut self) -> Result<(u8, u8), Self::Error> {
        T::codes(self)
    }
}

impl<T: ArmReports + ?Sized> ArmReports for Box<T> {
    fn next_report(&mut self) -> Result<ArmState, Self::Error> {
        T::next_report(self)
    }
}
