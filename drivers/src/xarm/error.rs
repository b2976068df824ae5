//! The xArm driver's error type and what each failure means to the safety code.

use super::codec::CodecError;
use super::codes;
use hitl_hal::ErrorKind;
use std::io;
use std::net::SocketAddr;

/// Everything that can go wrong talking to an xArm control box (or the stub).
#[derive(Debug, thiserror::Error)]
pub enum XarmError {
    #[error("cannot connect to the xArm at {addr}: {source}")]
    Connect { addr: SocketAddr, source: io::Error },
    #[error("xArm link failed: {0}")]
    Io(#[from] io::Error),
    #[error("the xArm closed the connection")]
    Closed,
    #[error("bad bytes from the xArm: {0}")]
    Codec(#[from] CodecError),
    #[error("the xArm did not answer {register} within {timeout_ms} ms")]
    NoReply { register: &'static str, timeout_ms: u64 },
    #[error("the xArm reports a controller error (reply to {register}, state byte {state:#04x})")]
    ArmFault { register: &'static str, state: u8 },
    #[error("the xArm is not ready to move (reply to {register}, state byte {state:#04x})")]
    NotReady { register: &'static str, state: u8 },
    #[error("the xArm refused {register} as invalid")]
    Invalid { register: &'static str },
    #[error("{0} servo_j replies outstanding: the xArm stopped answering")]
    Backlog(u32),
    #[error("xArm controller error {code} ({}), warning {warn}", codes::error_name(*.code).unwrap_or("unknown code"))]
    Controller { code: u8, warn: u8 },
    #[error("xArm state {state} after enabling: the arm is not ready to move")]
    EnableFailed { state: u8 },
}

fn io_kind(e: &io::Error) -> ErrorKind {
    match e.kind() {
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => ErrorKind::Timeout,
        io::ErrorKind::InvalidData => ErrorKind::Protocol,
        _ => ErrorKind::Disconnected,
    }
}

impl hitl_hal::Error for XarmError {
    fn kind(&self) -> ErrorKind {
        match self {
            XarmError::Connect { source, .. } => match source.kind() {
                io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => ErrorKind::Timeout,
                _ => ErrorKind::NotFound,
            },
            XarmError::Io(e) => io_kind(e),
            XarmError::Closed => ErrorKind::Disconnected,
            XarmError::Codec(_) => ErrorKind::Protocol,
            XarmError::NoReply { .. } | XarmError::Backlog(_) => ErrorKind::Timeout,
            XarmError::ArmFault { .. }
            | XarmError::NotReady { .. }
            | XarmError::Controller { .. }
            | XarmError::EnableFailed { .. } => ErrorKind::DeviceFault,
            XarmError::Invalid { .. } => ErrorKind::InvalidRequest,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_hal::Error;

    #[test]
    fn kinds_follow_the_failure() {
        assert_eq!(XarmError::Closed.kind(), ErrorKind::Disconnected);
        assert_eq!(XarmError::Codec(CodecError::Protocol(7)).kind(), ErrorKind::Protocol);
        assert_eq!(XarmError::Io(io::ErrorKind::TimedOut.into()).kind(), ErrorKind::Timeout);
        let e = XarmError::Controller { code: 23, warn: 0 };
        assert_eq!(e.kind(), ErrorKind::DeviceFault);
        assert!(e.to_string().contains("joint angle exceeds limit"), "{e}");
    }
}
