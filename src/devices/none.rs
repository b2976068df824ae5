//! Devices that are deliberately absent (`--camera none`, `--light none`, no input wiring, no
//! trigger lines). They accept every call and do nothing, so the loop's code is the same with or
//! without them.

use hitl_hal::{
    CaptureRequest, ErrorKind, ErrorType, FireReport, InputState, Inputs, Intrinsics, Lifecycle,
    Light, RgbdCamera, RgbdFrame, StreamConfig, Trigger, TriggerLines,
};

/// No camera: triggers are accepted and no frame ever arrives.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoCamera;

impl ErrorType for NoCamera {
    type Error = ErrorKind;
}

impl Lifecycle for NoCamera {}

impl RgbdCamera for NoCamera {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
        Ok(config.intrinsics)
    }
    fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
        Ok(())
    }
    fn trigger(&mut self, _request: CaptureRequest) -> Result<(), ErrorKind> {
        Ok(())
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
        Ok(None)
    }
}

/// No light: levels are accepted and ignored.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoLight;

impl ErrorType for NoLight {
    type Error = ErrorKind;
}

impl Lifecycle for NoLight {}

impl Light for NoLight {
    fn set_level(&mut self, _level: f32) -> Result<(), ErrorKind> {
        Ok(())
    }
}

/// No safety inputs wired to the controller: the e-stop is then the arm's own hardware circuit
/// and the door is not watched. `hitl run --arm` says so before it moves.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoInputs;

impl ErrorType for NoInputs {
    type Error = ErrorKind;
}

impl Lifecycle for NoInputs {}

impl Inputs for NoInputs {
    fn read(&mut self) -> Result<InputState, ErrorKind> {
        Ok(InputState::default())
    }
}

/// No trigger lines: the camera is triggered in software only.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoTrigger;

impl ErrorType for NoTrigger {
    type Error = ErrorKind;
}

impl Lifecycle for NoTrigger {}

impl Trigger for NoTrigger {
    fn fire(&mut self, _tick: u64, _lines: TriggerLines) -> Result<(), ErrorKind> {
        Ok(())
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, ErrorKind> {
        Ok(None)
    }
}
