//! Faults of the serial light and trigger drivers: the error type the HAL traits return, and the
//! lock-free health flag through which a driver's I/O task tells the tick that the device failed.
//!
//! A fault is sticky: the first one the task sees is kept and returned by every later call from
//! the tick, which never allocates to do so (the reasons are `'static`). Reopen the driver to clear.

use std::borrow::Cow;
use std::fmt;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use hitl_hal::{Error, ErrorKind};

/// Why a serial device stopped being usable. Each reason maps to one [`ErrorKind`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Fault {
    /// The port reported end of file or hang-up: the adapter was unplugged.
    Unplugged = 1,
    /// A write did not complete within the write timeout.
    WriteTimeout,
    /// A write or read failed with an I/O error.
    Io,
    /// The trigger box did not acknowledge a command within its deadline.
    AckTimeout,
    /// The trigger box sent no input report within the staleness limit.
    InputsStale,
    /// The trigger box sent a line that is not part of the protocol.
    Garbage,
    /// The trigger box sent a line longer than the protocol allows.
    LineTooLong,
    /// The trigger box acknowledged a command that was never sent.
    UnexpectedAck,
    /// The trigger box reported an error (`E` line).
    BoxError,
    /// The tick queued more commands than the device can take.
    QueueFull,
    /// The driver's I/O task ended (runtime shut down).
    TaskEnded,
    /// The trigger box sent its start banner after it was opened: it restarted, and its clock,
    /// light and the answers in flight are gone.
    BoxRestarted,
    /// The trigger box speaks another protocol version than the driver (or does not know `V`).
    WrongProtocol,
}

impl Fault {
    const ALL: [Fault; 13] = [
        Fault::Unplugged,
        Fault::WriteTimeout,
        Fault::Io,
        Fault::AckTimeout,
        Fault::InputsStale,
        Fault::Garbage,
        Fault::LineTooLong,
        Fault::UnexpectedAck,
        Fault::BoxError,
        Fault::QueueFull,
        Fault::TaskEnded,
        Fault::BoxRestarted,
        Fault::WrongProtocol,
    ];

    /// The HAL error kind the safety code sees.
    pub fn kind(self) -> ErrorKind {
        match self {
            Fault::Unplugged | Fault::TaskEnded => ErrorKind::Disconnected,
            Fault::WriteTimeout | Fault::AckTimeout | Fault::InputsStale => ErrorKind::Timeout,
            Fault::Garbage | Fault::LineTooLong | Fault::UnexpectedAck | Fault::WrongProtocol => {
                ErrorKind::Protocol
            }
            Fault::Io | Fault::BoxError | Fault::QueueFull | Fault::BoxRestarted => {
                ErrorKind::DeviceFault
            }
        }
    }

    /// A fixed sentence for logs and `/safety/event` records.
    pub fn message(self) -> &'static str {
        match self {
            Fault::Unplugged => "serial port closed or hung up (adapter unplugged?)",
            Fault::WriteTimeout => "serial write did not complete within the write timeout",
            Fault::Io => "serial I/O error",
            Fault::AckTimeout => "trigger box did not acknowledge a command in time",
            Fault::InputsStale => "trigger box input reports (e-stop, door) are stale",
            Fault::Garbage => "trigger box sent a line that is not part of the protocol",
            Fault::LineTooLong => "trigger box sent an over-long line",
            Fault::UnexpectedAck => "trigger box acknowledged a command that was not sent",
            Fault::BoxError => "trigger box reported an error",
            Fault::QueueFull => "command queue to the serial device is full",
            Fault::TaskEnded => "serial I/O task has ended",
            Fault::BoxRestarted => {
                "trigger box restarted (its start banner came after it was opened): its clock, \
                 light and the answers in flight are gone"
            }
            Fault::WrongProtocol => {
                "trigger box speaks another protocol version than this driver (2); flash \
                 firmware/trigger-box (docs/trigger-box.md)"
            }
        }
    }

    fn from_code(code: u8) -> Option<Fault> {
        Fault::ALL.iter().copied().find(|f| *f as u8 == code)
    }
}

/// Error of the serial light and trigger drivers: a kind and a message naming the problem.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SerialError {
    kind: ErrorKind,
    message: Cow<'static, str>,
}

impl SerialError {
    pub fn new(kind: ErrorKind, message: impl Into<Cow<'static, str>>) -> Self {
        Self { kind, message: message.into() }
    }
    pub fn message(&self) -> &str {
        &self.message
    }
}

impl From<Fault> for SerialError {
    fn from(f: Fault) -> Self {
        Self { kind: f.kind(), message: Cow::Borrowed(f.message()) }
    }
}

impl From<ErrorKind> for SerialError {
    fn from(kind: ErrorKind) -> Self {
        Self { kind, message: Cow::Borrowed(kind.as_str()) }
    }
}

impl fmt::Display for SerialError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.message, self.kind)
    }
}

impl std::error::Error for SerialError {}

impl Error for SerialError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}

/// The sticky, lock-free health flag shared by a driver handle and its I/O task.
#[derive(Debug, Default)]
pub struct Health {
    code: AtomicU8,
}

impl Health {
    pub const fn new() -> Self {
        Self { code: AtomicU8::new(0) }
    }

    /// Record a fault unless one is already recorded (the first cause is the one that matters).
    pub fn trip(&self, fault: Fault) {
        let _ = self.code.compare_exchange(0, fault as u8, Ordering::AcqRel, Ordering::Acquire);
    }

    /// The recorded fault, if any.
    pub fn fault(&self) -> Option<Fault> {
        Fault::from_code(self.code.load(Ordering::Acquire))
    }

    /// `Ok` while healthy, else the recorded fault as an error. Never allocates.
    pub fn check(&self) -> Result<(), SerialError> {
        match self.fault() {
            None => Ok(()),
            Some(f) => Err(f.into()),
        }
    }
}

/// The end of a driver's I/O task, as its handle sees it: the task holds the [`TaskEnd`] sender
/// half and drops it when it returns (or is aborted), which wakes [`TaskEnd::wait`] at once.
#[derive(Debug)]
pub struct TaskEnd(mpsc::Receiver<()>);

/// Held by the I/O task; dropping it says the task has ended.
#[derive(Debug)]
pub struct TaskAlive(#[allow(dead_code)] mpsc::SyncSender<()>);

impl TaskEnd {
    pub fn new() -> (TaskAlive, TaskEnd) {
        let (tx, rx) = mpsc::sync_channel(1);
        (TaskAlive(tx), TaskEnd(rx))
    }

    /// Whether the task has ended (never blocks, never allocates).
    pub fn has_ended(&self) -> bool {
        matches!(self.0.try_recv(), Err(mpsc::TryRecvError::Disconnected) | Ok(()))
    }

    /// Block (outside the runtime) until the task has ended; `false` when `timeout` passed first.
    pub fn wait(&self, timeout: Duration) -> bool {
        matches!(self.0.recv_timeout(timeout), Err(mpsc::RecvTimeoutError::Disconnected) | Ok(()))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn first_fault_sticks_and_maps_to_its_kind() {
        let h = Health::new();
        assert!(h.check().is_ok());
        h.trip(Fault::WriteTimeout);
        h.trip(Fault::Unplugged);
        assert_eq!(h.fault(), Some(Fault::WriteTimeout));
        let e = h.check().unwrap_err();
        assert_eq!(Error::kind(&e), ErrorKind::Timeout);
    }

    #[test]
    fn every_fault_round_trips_through_its_code() {
        for f in Fault::ALL {
            assert_eq!(Fault::from_code(f as u8), Some(f));
        }
        assert_eq!(Fault::from_code(0), None);
    }
}
