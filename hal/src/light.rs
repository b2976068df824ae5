//! The studio light that plays the Sun.

use crate::error::ErrorType;

/// A dimmable light. Called from the tick: implementations queue the change and must not block.
///
/// There is no strobe here: a flash that goes with a capture is the trigger's strobe line
/// ([`crate::Trigger::fire`] with [`crate::TriggerLines`]), timed by the hardware, not a light
/// command from the tick.
pub trait Light: ErrorType {
    /// Set the level, 0.0 (off) to 1.0 (full).
    fn set_level(&mut self, level: f32) -> Result<(), Self::Error>;
}

impl<T: Light + ?Sized> Light for &mut T {
    fn set_level(&mut self, level: f32) -> Result<(), Self::Error> {
        T::set_level(self, level)
    }
}

impl<T: Light + ?Sized> Light for Box<T> {
    fn set_level(&mut self, level: f32) -> Result<(), Self::Error> {
        T::set_level(self, level)
    }
}
