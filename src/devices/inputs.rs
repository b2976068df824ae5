//! The safety inputs a run reads, from every source wired: the stub's simulated e-stop and door,
//! the trigger box's input lines, or none. Sources are combined: the e-stop reads pressed when
//! any source says so, the door open likewise, and a source that fails fails them all (the
//! interlock then treats the inputs as unknown, which is unsafe).

use super::any::InputsDevice;
use hitl_hal::{ErrorKind, ErrorType, InputState, Inputs, Lifecycle};

/// Every input source of the run, read together.
#[derive(Default)]
pub struct RunInputs {
    sources: Vec<(String, Box<dyn InputsDevice>)>,
}

impl RunInputs {
    /// No inputs wired (until [`RunInputs::add`]).
    pub fn none() -> Self {
        Self::default()
    }

    /// Add a source, named for messages.
    pub fn add(&mut self, name: impl Into<String>, source: Box<dyn InputsDevice>) {
        self.sources.push((name.into(), source));
    }

    /// The sources' names.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.sources.iter().map(|(n, _)| n.as_str())
    }

    /// The first source that failed and why, in words (after the run).
    pub fn fault_text(&self) -> Option<String> {
        self.sources.iter().find_map(|(name, s)| s.fault_text().map(|why| format!("{name}: {why}")))
    }
}

impl ErrorType for RunInputs {
    type Error = ErrorKind;
}

impl Inputs for RunInputs {
    fn read(&mut self) -> Result<InputState, ErrorKind> {
        let mut all = InputState::default();
        for (_, source) in &mut self.sources {
            let s = source.read()?;
            all.estop_pressed |= s.estop_pressed;
            all.door_open |= s.door_open;
        }
        Ok(all)
    }
}

impl Lifecycle for RunInputs {
    fn start(&mut self) -> Result<(), ErrorKind> {
        self.sources.iter_mut().try_for_each(|(_, s)| s.start())
    }
    fn health(&mut self) -> Result<(), ErrorKind> {
        self.sources.iter_mut().try_for_each(|(_, s)| s.health())
    }
    /// Stops every source, even after one failed to stop; returns the first failure.
    fn stop(&mut self) -> Result<(), ErrorKind> {
        let mut first = Ok(());
        for (_, s) in &mut self.sources {
            let r = s.stop();
            if first.is_ok() {
                first = r;
            }
        }
        first
    }
}
