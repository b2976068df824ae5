//! `hitl-hal`: the traits and plain data types between the controller and its devices.
//!
//! Modelled on embedded-hal: every device trait is small, names its error through [`ErrorType`],
//! and every error maps to a shared [`ErrorKind`] so the safety code can decide what a fault means
//! (stop with motion, hold, or give up on the device) without knowing which driver is behind it.
//! Nothing here does I/O or allocates on its own; drivers live in `hitl-drivers` and `hitl-sim-stub`.

pub mod arm;
pub mod camera;
pub mod clock;
pub mod error;
pub mod inputs;
pub mod light;
pub mod trigger;

pub use arm::{Arm, ArmReports, ArmState, Joints, DOF};
pub use camera::{CaptureRequest, Intrinsics, RgbdCamera, RgbdFrame, StreamConfig};
pub use clock::{Clock, MonotonicClock};
pub use error::{Error, ErrorKind, ErrorType};
pub use inputs::{InputState, Inputs};
pub use light::Light;
pub use trigger::{FireReport, Trigger, TriggerLines};
