//! Hardware trigger lines (camera trigger, light strobe) and the times they actually fired.

use crate::error::ErrorType;

/// Which lines to fire together.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TriggerLines {
    pub camera: bool,
    pub light: bool,
}

/// A fire acknowledged by the trigger device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FireReport {
    /// The tick the fire was asked for.
    pub tick: u64,
    /// When the device says it fired, on its own clock, microseconds.
    pub device_us: u64,
    /// Host monotonic time the acknowledgement arrived, nanoseconds.
    pub acked_ns: u64,
    /// When it fired on the host's monotonic clock, nanoseconds: `device_us` through the
    /// device's clock mapping (`None` where the device's clock is not mapped).
    pub host_ns: Option<u64>,
    /// A bound on `host_ns`'s error, nanoseconds.
    pub host_error_ns: Option<u64>,
}

/// A device that fires trigger lines. `fire` is called from the tick and must not block.
pub trait Trigger: ErrorType {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), Self::Error>;
    /// Take an acknowledged fire if one arrived (never blocks).
    fn poll_fired(&mut self) -> Result<Option<FireReport>, Self::Error>;
}

impl<T: Trigger + ?Sized> Trigger for &mut T {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), Self::Error> {
        T::fire(self, tick, lines)
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, Self::Error> {
        T::poll_fired(self)
    }
}

impl<T: Trigger + ?Sized> Trigger for Box<T> {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), Self::Error> {
        T::fire(self, tick, lines)
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, Self::Error> {
        T::poll_fired(self)
    }
}
