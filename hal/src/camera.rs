//! RGB-D cameras that capture on a trigger from the tick and deliver frames later.

use crate::error::ErrorType;
use std::sync::Arc;

/// One image buffer of a frame, shared rather than copied: the recorder and perception hold the
/// same pixels (cloning it clones the pointer). Built from the `Vec` a camera fills, without
/// copying (`Arc::new(vec)`).
pub type SharedPixels<T> = Arc<Vec<T>>;

/// Pinhole intrinsics of the colour and depth streams (registered to each other), OpenCV axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// What the controller asks of a camera before a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamConfig {
    pub intrinsics: Intrinsics,
    /// Also deliver a target segmentation mask (only simulated cameras can).
    pub mask: bool,
}

/// One capture fired by the tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureRequest {
    /// Tick at which the trigger fired.
    pub tick: u64,
    /// Host monotonic time of the trigger, nanoseconds.
    pub fired_ns: u64,
}

/// Where a frame's `exposure_ns` comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimestampSource {
    /// The exposure itself: the device's global timestamp (its exposure clock fitted to the
    /// host's), or a simulated camera's exact capture time.
    DeviceExposure,
    /// The host's arrival time of the frame: later than the exposure by the transfer time.
    HostArrival,
}

/// A frame delivered by a camera, matched to the capture that caused it.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbdFrame {
    /// The capture request this frame answers.
    pub request: CaptureRequest,
    /// Exposure time on the device's clock, nanoseconds.
    pub device_ns: u64,
    /// Exposure time on the host's monotonic clock, nanoseconds (after clock mapping).
    pub exposure_ns: u64,
    /// What `exposure_ns` was measured from: the exposure itself, or the frame's arrival.
    pub timestamp: TimestampSource,
    pub intrinsics: Intrinsics,
    /// Colour, rgb8, row-major, `width * height * 3` bytes.
    pub color: SharedPixels<u8>,
    /// Depth in metres, row-major; 0 where there is no return.
    pub depth_m: SharedPixels<f32>,
    /// Target mask, mono8 (255 target, 0 else), when the camera can give one.
    pub mask: Option<SharedPixels<u8>>,
}

/// An RGB-D camera in software- or hardware-triggered mode.
pub trait RgbdCamera: ErrorType {
    /// Configure streams; returns the intrinsics the device will deliver.
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, Self::Error>;
    /// Put the camera in triggered mode so that every `trigger` yields one frame.
    fn arm_trigger(&mut self) -> Result<(), Self::Error>;
    /// Fire one capture. Called from the tick: must not allocate or block.
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), Self::Error>;
    /// Take a delivered frame if one is ready (never blocks).
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, Self::Error>;
}

impl<T: RgbdCamera + ?Sized> RgbdCamera for &mut T {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, Self::Error> {
        T::configure(self, config)
    }
    fn arm_trigger(&mut self) -> Result<(), Self::Error> {
        T::arm_trigger(self)
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), Self::Error> {
        T::trigger(self, request)
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, Self::Error> {
        T::poll_frame(self)
    }
}

impl<T: RgbdCamera + ?Sized> RgbdCamera for Box<T> {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, Self::Error> {
        T::configure(self, config)
    }
    fn arm_trigger(&mut self) -> Result<(), Self::Error> {
        T::arm_trigger(self)
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), Self::Error> {
        T::trigger(self, request)
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, Self::Error> {
        T::poll_frame(self)
    }
}
