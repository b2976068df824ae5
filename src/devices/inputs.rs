//! The safety inputs a run reads, whichever device provides them: the stub's simulated e-stop and
//! door, the trigger box's input lines, or none wired.

use super::none::NoInputs;
use hitl_hal::{Error as _, ErrorKind, ErrorType, InputState, Inputs};

/// One of the input sources, behind one type so the loop has a single shape.
pub enum RunInputs {
    None(NoInputs),
    #[cfg(feature = "stub")]
    Sim(hitl_sim_stub::SimInputsReader),
    TriggerBox(hitl_drivers::light::TriggerBox),
}

impl ErrorType for RunInputs {
    type Error = ErrorKind;
}

impl Inputs for RunInputs {
    fn read(&mut self) -> Result<InputState, ErrorKind> {
        match self {
            RunInputs::None(n) => n.read(),
            #[cfg(feature = "stub")]
            RunInputs::Sim(s) => s.read(),
            RunInputs::TriggerBox(t) => t.read().map_err(|e| e.kind()),
        }
    }
}
