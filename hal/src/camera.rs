//! RGB-D cameras that capture on a trigger from the tick and deliver frames later.

use crate::error::ErrorType;

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

/// A frame delivered by a camera, matched to the capture that caused it.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbdFrame {
    /// The capture request this frame answers.
    pub request: CaptureRequest,
    /// Exposure time on the device's clock, nanoseconds.
    pub device_ns: u64,
    /// Exposure time on the host's monotonic clock, nanoseconds (after clock mapping).
    pub exposure_ns: u64,
    pub intrinsics: Intrinsics,
    /// Colour, rgb8, row-major, `width * height * 3` bytes.
    pub color: Vec<u8>,
    /// Depth in metres, row-major; 0 where there is no return.
    pub depth_m: Vec<f32>,
    /// Target mask, mono8 (255 target, 0 else), when the camera can give one.
    pub mask: Option<Vec<u8>>,
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
