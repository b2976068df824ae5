//! The life of a device in a run, in the spirit of copper-rs's task lifecycle: opened (by its
//! driver's constructor), started, checked every tick, stopped. Every step has a no-op default,
//! so a device implements only the steps it needs.
//!
//! When the session calls each step (src/session, docs/devices.md):
//!
//! 1. **open** is the driver's own constructor (`DmxLight::open`, `TriggerBox::open`, ...): it
//!    claims the port or device and checks that it answers. Nothing moves yet.
//! 2. [`Lifecycle::start`]: once every device of the run is open and configured (a camera after
//!    `configure` and `arm_trigger`), before the arm is enabled. A device begins to do its job
//!    here (stream, refresh, watch); a device that cannot start fails the run with exit 5 before
//!    anything moved.
//! 3. [`Lifecycle::health`]: from the real-time tick, every period. It says whether the device
//!    still works as far as the driver already knows (a sticky fault flag), so a fault is seen
//!    within one tick even when the tick has nothing to ask the device. Must not block, allocate
//!    or do I/O.
//! 4. [`Lifecycle::stop`]: once, after the loop has ended (completed or tripped) and the arm is at
//!    rest or holding. The device finishes what it was doing (a last frame, queued commands),
//!    lets go of its port and its I/O task, and returns; it is not used again. Bounded: a device
//!    that does not finish within its own timeout gives up and says so.

use crate::error::ErrorType;

/// The steps of a device's life in a run (see the module documentation for when each is called).
pub trait Lifecycle: ErrorType {
    /// Begin the device's work; called once, before the arm is enabled.
    fn start(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
    /// Whether the device still works, from what the driver already knows. Called from the tick
    /// every period: no blocking, no allocation, no I/O.
    fn health(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
    /// Finish and let go of the device; called once, after the loop.
    fn stop(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl<T: Lifecycle + ?Sized> Lifecycle for &mut T {
    fn start(&mut self) -> Result<(), Self::Error> {
        T::start(self)
    }
    fn health(&mut self) -> Result<(), Self::Error> {
        T::health(self)
    }
    fn stop(&mut self) -> Result<(), Self::Error> {
        T::stop(self)
    }
}

impl<T: Lifecycle + ?Sized> Lifecycle for Box<T> {
    fn start(&mut self) -> Result<(), Self::Error> {
        T::start(self)
    }
    fn health(&mut self) -> Result<(), Self::Error> {
        T::health(self)
    }
    fn stop(&mut self) -> Result<(), Self::Error> {
        T::stop(self)
    }
}
