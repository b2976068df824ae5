//! The studio light that plays the Sun.

use crate::error::{ErrorKind, ErrorType};

/// A dimmable light. Called from the tick: implementations queue the change and must not block.
pub trait Light: ErrorType {
    /// Set the level, 0.0 (off) to 1.0 (full).
    fn set_level(&mut self, level: f32) -> Result<(), Self::Error>;
    /// Flash at `level` for `duration_us` microseconds, where the light can strobe.
    fn strobe(&mut self, level: f32, duration_us: u32) -> Result<(), Self::Error>
    where
        Self::Error: From<ErrorKind>,
    {
        let _ = (level, duration_us);
        Err(ErrorKind::InvalidRequest.into())
    }
}

impl<T: Light + ?Sized> Light for &mut T {
    fn set_level(&mut self, level: f32) -> Result<(), Self::Error> {
        T::set_level(self, level)
    }
    fn strobe(&mut self, level: f32, duration_us: u32) -> Result<(), Self::Error>
    where
        Self::Error: From<ErrorKind>,
    {
        T::strobe(self, level, duration_us)
    }
}

impl<T: Light + ?Sized> Light for Box<T> {
    fn set_level(&mut self, level: f32) -> Result<(), Self::Error> {
        T::set_level(self, level)
    }
    fn strobe(&mut self, level: f32, duration_us: u32) -> Result<(), Self::Error>
    where
        Self::Error: From<ErrorKind>,
    {
        T::strobe(self, level, duration_us)
    }
}
