//! `hitl-hal`: the traits and plain data types between the controller and its devices.
//!
//! Modelled on embedded-hal: every device trait is small, names its error through [`ErrorType`],
//! and every error maps to a shared [`ErrorKind`] so the safety code can decide what a fault means
//! (stop with motion, hold, or give up on the device) without knowing which driver is behind it.
//! Every trait is also implemented for `&mut T` (as embedded-hal does), so the real-time loop
//! can borrow its devices from the session instead of owning them, and for `Box<T>`, so a run can
//! hold a device chosen at run time as a trait object.
//! [`Pose`] (module [`pose`]) is the workspace's one rigid-transform type.
//! Nothing here does I/O or allocates on its own; drivers live in `hitl-drivers` and `hitl-sim-stub`.

pub mod arm;
pub mod camera;
pub mod clock;
pub mod error;
pub mod inputs;
pub mod lens;
pub mod lifecycle;
pub mod light;
pub mod motion;
pub mod pose;
pub mod trigger;

pub use arm::{Arm, ArmReports, ArmState, Joints, DOF};
pub use camera::{
    CaptureRequest, Intrinsics, RgbdCamera, RgbdFrame, SharedPixels, StreamConfig, TimestampSource,
};
pub use clock::{Clock, MonotonicClock, SimTime};
pub use error::{Error, ErrorKind, ErrorType};
pub use inputs::{InputState, Inputs};
pub use lens::{Distortion, DistortionModel};
pub use lifecycle::Lifecycle;
pub use light::Light;
pub use motion::{JointState, Phase};
pub use pose::Pose;
pub use trigger::{FireReport, Trigger, TriggerLines};

#[cfg(test)]
mod tests {
    use super::*;

    struct Counter(u32);
    impl ErrorType for Counter {
        type Error = ErrorKind;
    }
    impl Light for Counter {
        fn set_level(&mut self, _level: f32) -> Result<(), ErrorKind> {
            self.0 += 1;
            Ok(())
        }
    }
    impl Lifecycle for Counter {}

    fn drive<L: Light + Lifecycle>(mut light: L) -> Result<(), L::Error> {
        light.start()?;
        light.set_level(0.5)?;
        light.health()?;
        light.stop()
    }

    /// A borrowed device is a device: the loop drives `&mut T` and the owner keeps `T`.
    #[test]
    fn a_mutable_borrow_drives_the_owned_device() {
        let mut light = Counter(0);
        assert_eq!(drive(&mut light), Ok(()));
        assert_eq!(drive(&mut &mut light), Ok(()));
        assert_eq!(light.0, 2);
    }
}
