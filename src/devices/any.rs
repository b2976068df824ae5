//! The camera and light a run drives, whichever device is behind them, as one type each so the
//! loop has a single shape. Driver errors reach the loop as their `ErrorKind`.

use super::none::{NoCamera, NoLight};
use hitl_drivers::light::SerialLight;
use hitl_drivers::orbbec::OrbbecCamera;
use hitl_hal::{
    CaptureRequest, Error as _, ErrorKind, ErrorType, Intrinsics, Light, RgbdCamera, RgbdFrame,
    StreamConfig,
};

/// The run's camera.
pub enum RunCamera {
    None(NoCamera),
    #[cfg(feature = "stub")]
    Sim(Box<hitl_sim_stub::camera::SimCamera>),
    Orbbec(Box<OrbbecCamera>),
}

macro_rules! on_camera {
    ($self:expr, $c:ident => $body:expr) => {
        match $self {
            RunCamera::None($c) => $body.map_err(|e| e.kind()),
            #[cfg(feature = "stub")]
            RunCamera::Sim($c) => $body.map_err(|e| e.kind()),
            RunCamera::Orbbec($c) => $body.map_err(|e| e.kind()),
        }
    };
}

impl ErrorType for RunCamera {
    type Error = ErrorKind;
}

impl RgbdCamera for RunCamera {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
        on_camera!(self, c => c.configure(config))
    }
    fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
        on_camera!(self, c => c.arm_trigger())
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), ErrorKind> {
        on_camera!(self, c => c.trigger(request))
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
        on_camera!(self, c => c.poll_frame())
    }
}

/// The run's light.
pub enum RunLight {
    None(NoLight),
    #[cfg(feature = "stub")]
    Sim(crate::capture::sim_light::SimLight),
    Serial(SerialLight),
}

impl ErrorType for RunLight {
    type Error = ErrorKind;
}

impl Light for RunLight {
    fn set_level(&mut self, level: f32) -> Result<(), ErrorKind> {
        match self {
            RunLight::None(l) => l.set_level(level),
            #[cfg(feature = "stub")]
            RunLight::Sim(l) => l.set_level(level),
            RunLight::Serial(l) => l.set_level(level).map_err(|e| e.kind()),
        }
    }
}
