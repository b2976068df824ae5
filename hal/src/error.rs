//! The shared error vocabulary: what a device fault *means* to the safety code.

use core::fmt;

/// What kind of fault a device reported, as the safety code needs to know it.
///
/// The interlocks map kinds to actions: a [`ErrorKind::DeviceFault`] of the arm still allows a
/// controlled stop, a [`ErrorKind::Disconnected`] arm does not; a camera or light fault ends the
/// run with the device/connection exit code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The link to the device is gone (socket closed, port unplugged, peer reset).
    Disconnected,
    /// The device did not answer within its deadline.
    Timeout,
    /// Bytes from the device made no sense: bad framing, wrong protocol id, absurd length.
    Protocol,
    /// The device reports a fault of its own (arm error code, camera error state).
    DeviceFault,
    /// The device is not present or could not be opened.
    NotFound,
    /// The request was refused: out of range, wrong mode or state, unsupported.
    InvalidRequest,
    /// Anything else; the safety code treats it like a device fault.
    Other,
}

impl ErrorKind {
    /// A short lower-case name for logs and `/safety/event` records.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorKind::Disconnected => "disconnected",
            ErrorKind::Timeout => "timeout",
            ErrorKind::Protocol => "protocol",
            ErrorKind::DeviceFault => "device-fault",
            ErrorKind::NotFound => "not-found",
            ErrorKind::InvalidRequest => "invalid-request",
            ErrorKind::Other => "other",
        }
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A device error that can say which [`ErrorKind`] it is.
pub trait Error: fmt::Debug + fmt::Display + Send + 'static {
    fn kind(&self) -> ErrorKind;
}

impl Error for ErrorKind {
    fn kind(&self) -> ErrorKind {
        *self
    }
}

/// Names the error type of a device trait (embedded-hal's `ErrorType`).
pub trait ErrorType {
    type Error: Error;
}

impl<T: ErrorType + ?Sized> ErrorType for &mut T {
    type Error = T::Error;
}

impl<T: ErrorType + ?Sized> ErrorType for Box<T> {
    type Error = T::Error;
}
