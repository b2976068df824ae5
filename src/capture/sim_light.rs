//! The stub's Sun: `--light sim` sets the level the simulated camera shades with.

use hitl_hal::{ErrorKind, ErrorType, Lifecycle, Light};

/// Sets the simulated Sun's level (lock-free).
#[derive(Debug, Clone)]
pub struct SimLight(pub hitl_sim_stub::camera::LightLevel);

impl ErrorType for SimLight {
    type Error = ErrorKind;
}

/// Nothing to start or stop: the level is a shared cell.
impl Lifecycle for SimLight {}

impl Light for SimLight {
    fn set_level(&mut self, level: f32) -> Result<(), ErrorKind> {
        if !(0.0..=1.0).contains(&level) {
            return Err(ErrorKind::InvalidRequest);
        }
        self.0.set(level);
        Ok(())
    }
}
