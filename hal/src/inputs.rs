//! Safety inputs wired to the enclosure: the e-stop button and the door switch.

use crate::error::ErrorType;

/// Safety inputs as last read. `true` means the unsafe condition holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InputState {
    pub estop_pressed: bool,
    pub door_open: bool,
}

/// Reads the safety inputs. Called from the tick: must not block.
pub trait Inputs: ErrorType {
    fn read(&mut self) -> Result<InputState, Self::Error>;
}

impl<T: Inputs + ?Sized> Inputs for &mut T {
    fn read(&mut self) -> Result<InputState, Self::Error> {
        T::read(self)
    }
}

impl<T: Inputs + ?Sized> Inputs for Box<T> {
    fn read(&mut self) -> Result<InputState, Self::Error> {
        T::read(self)
    }
}
