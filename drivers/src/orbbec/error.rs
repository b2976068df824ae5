//! Errors of the Orbbec driver: a HAL kind and a message that names the Orbbec camera.

use std::borrow::Cow;
use std::fmt;

use hitl_hal::{Error, ErrorKind};

use super::ffi::{
    SdkError, OB_EXCEPTION_TYPE_CAMERA_DISCONNECTED, OB_EXCEPTION_TYPE_DEVICE_UNAVAILABLE,
    OB_EXCEPTION_TYPE_INVALID_VALUE, OB_EXCEPTION_TYPE_NOT_FOUND,
    OB_EXCEPTION_TYPE_UNSUPPORTED_OPERATION,
};

/// An Orbbec camera error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OrbbecError {
    kind: ErrorKind,
    message: Cow<'static, str>,
}

impl OrbbecError {
    pub fn new(kind: ErrorKind, message: impl Into<Cow<'static, str>>) -> Self {
        Self { kind, message: message.into() }
    }

    pub fn message(&self) -> &str {
        &self.message
    }

    /// An SDK error during `doing`, classified by the SDK's exception type.
    pub(crate) fn sdk(doing: &str, e: &SdkError) -> Self {
        let kind = match e.exception {
            OB_EXCEPTION_TYPE_CAMERA_DISCONNECTED => ErrorKind::Disconnected,
            OB_EXCEPTION_TYPE_DEVICE_UNAVAILABLE | OB_EXCEPTION_TYPE_NOT_FOUND => {
                ErrorKind::NotFound
            }
            OB_EXCEPTION_TYPE_INVALID_VALUE | OB_EXCEPTION_TYPE_UNSUPPORTED_OPERATION => {
                ErrorKind::InvalidRequest
            }
            _ => ErrorKind::DeviceFault,
        };
        Self::new(kind, format!("Orbbec camera: {doing}: {e}"))
    }
}

impl From<ErrorKind> for OrbbecError {
    fn from(kind: ErrorKind) -> Self {
        Self::new(kind, "Orbbec camera: request refused")
    }
}

impl fmt::Display for OrbbecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.message, self.kind)
    }
}

impl std::error::Error for OrbbecError {}

impl Error for OrbbecError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}
