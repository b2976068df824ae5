//! The run's devices as trait objects behind the run's one error type ([`ErrorKind`]), so the
//! loop has a single shape whichever drivers were chosen, and so no code outside `src/devices`
//! and the drivers' registries names a driver.
//!
//! [`Kinds`] turns a driver's errors into their [`ErrorKind`] for the loop and keeps the first
//! full error (moved, not formatted: nothing is allocated on the tick) for the messages written
//! after the run. [`Unmanaged`] gives a device that has no lifecycle of its own the no-op one.

use hitl_hal::{
    CaptureRequest, Error as _, ErrorKind, ErrorType, FireReport, InputState, Inputs, Intrinsics,
    Lifecycle, Light, RgbdCamera, RgbdFrame, StreamConfig, Trigger, TriggerLines,
};

/// Says why a device failed, after the run (formatting allocates: never from the tick).
pub trait Faulted {
    fn fault_text(&self) -> Option<String>;
}

/// A device whose errors reach the loop as their [`ErrorKind`]; the first error is kept.
pub struct Kinds<T: ErrorType> {
    dev: T,
    first: Option<T::Error>,
}

impl<T: ErrorType> Kinds<T> {
    pub fn new(dev: T) -> Self {
        Self { dev, first: None }
    }

    fn note(&mut self, e: T::Error) -> ErrorKind {
        let kind = e.kind();
        if self.first.is_none() {
            self.first = Some(e);
        }
        kind
    }
}

impl<T: ErrorType> ErrorType for Kinds<T> {
    type Error = ErrorKind;
}

impl<T: ErrorType> Faulted for Kinds<T> {
    fn fault_text(&self) -> Option<String> {
        self.first.as_ref().map(|e| e.to_string())
    }
}

impl<T: Lifecycle> Lifecycle for Kinds<T> {
    fn start(&mut self) -> Result<(), ErrorKind> {
        self.dev.start().map_err(|e| self.note(e))
    }
    fn health(&mut self) -> Result<(), ErrorKind> {
        self.dev.health().map_err(|e| self.note(e))
    }
    fn stop(&mut self) -> Result<(), ErrorKind> {
        self.dev.stop().map_err(|e| self.note(e))
    }
}

impl<T: Light> Light for Kinds<T> {
    fn set_level(&mut self, level: f32) -> Result<(), ErrorKind> {
        self.dev.set_level(level).map_err(|e| self.note(e))
    }
}

impl<T: Inputs> Inputs for Kinds<T> {
    fn read(&mut self) -> Result<InputState, ErrorKind> {
        self.dev.read().map_err(|e| self.note(e))
    }
}

impl<T: Trigger> Trigger for Kinds<T> {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), ErrorKind> {
        self.dev.fire(tick, lines).map_err(|e| self.note(e))
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, ErrorKind> {
        self.dev.poll_fired().map_err(|e| self.note(e))
    }
}

impl<T: RgbdCamera> RgbdCamera for Kinds<T> {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
        self.dev.configure(config).map_err(|e| self.note(e))
    }
    fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
        self.dev.arm_trigger().map_err(|e| self.note(e))
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), ErrorKind> {
        // Busy is not a fault (the capture is lost, the camera still works): not kept.
        self.dev.trigger(request).map_err(|e| match e.kind() {
            ErrorKind::Timeout => ErrorKind::Timeout,
            _ => self.note(e),
        })
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
        self.dev.poll_frame().map_err(|e| self.note(e))
    }
}

/// A device with no lifecycle steps of its own (the stub's simulated devices, a driver that does
/// all its work in `open` and `Drop`): every step is the no-op default.
pub struct Unmanaged<T>(pub T);

impl<T: ErrorType> ErrorType for Unmanaged<T> {
    type Error = T::Error;
}

impl<T: ErrorType> Lifecycle for Unmanaged<T> {}

impl<T: RgbdCamera> RgbdCamera for Unmanaged<T> {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, T::Error> {
        self.0.configure(config)
    }
    fn arm_trigger(&mut self) -> Result<(), T::Error> {
        self.0.arm_trigger()
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), T::Error> {
        self.0.trigger(request)
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, T::Error> {
        self.0.poll_frame()
    }
}

impl<T: Inputs> Inputs for Unmanaged<T> {
    fn read(&mut self) -> Result<InputState, T::Error> {
        self.0.read()
    }
}

/// A camera as the run holds it.
pub trait CameraDevice:
    RgbdCamera + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send
{
}
impl<T: RgbdCamera + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send> CameraDevice for T {}

/// A light as the run holds it.
pub trait LightDevice: Light + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send {}
impl<T: Light + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send> LightDevice for T {}

/// A source of safety inputs as the run holds it.
pub trait InputsDevice: Inputs + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send {}
impl<T: Inputs + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send> InputsDevice for T {}

/// Trigger lines as the run holds them.
pub trait TriggerDevice:
    Trigger + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send
{
}
impl<T: Trigger + Lifecycle + Faulted + ErrorType<Error = ErrorKind> + Send> TriggerDevice for T {}

/// Implements the lifecycle and the fault text of a `Run*` holder by delegating to `self.dev`.
macro_rules! holder {
    ($t:ty) => {
        impl ErrorType for $t {
            type Error = ErrorKind;
        }
        impl Lifecycle for $t {
            fn start(&mut self) -> Result<(), ErrorKind> {
                self.dev.start()
            }
            fn health(&mut self) -> Result<(), ErrorKind> {
                self.dev.health()
            }
            fn stop(&mut self) -> Result<(), ErrorKind> {
                self.dev.stop()
            }
        }
        impl $t {
            /// What the device is, for messages ("DMX light on /dev/ttyUSB0").
            pub fn name(&self) -> &str {
                &self.name
            }
            /// The first error the device returned, in words (after the run).
            pub fn fault_text(&self) -> Option<String> {
                self.dev.fault_text()
            }
        }
    };
}

/// The run's camera.
pub struct RunCamera {
    pub(crate) dev: Box<dyn CameraDevice>,
    pub(crate) name: String,
    /// `false` for `--camera none`: no frame will ever come.
    pub(crate) delivers_frames: bool,
}
holder!(RunCamera);

impl RunCamera {
    pub fn delivers_frames(&self) -> bool {
        self.delivers_frames
    }
}

impl RgbdCamera for RunCamera {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
        self.dev.configure(config)
    }
    fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
        self.dev.arm_trigger()
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), ErrorKind> {
        self.dev.trigger(request)
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
        self.dev.poll_frame()
    }
}

/// The run's light.
pub struct RunLight {
    pub(crate) dev: Box<dyn LightDevice>,
    pub(crate) name: String,
}
holder!(RunLight);

impl Light for RunLight {
    fn set_level(&mut self, level: f32) -> Result<(), ErrorKind> {
        self.dev.set_level(level)
    }
}

/// The run's trigger lines (the trigger box's, or none).
pub struct RunTrigger {
    pub(crate) dev: Box<dyn TriggerDevice>,
    pub(crate) name: String,
}
holder!(RunTrigger);

impl Trigger for RunTrigger {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), ErrorKind> {
        self.dev.fire(tick, lines)
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, ErrorKind> {
        self.dev.poll_fired()
    }
}
