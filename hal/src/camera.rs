//! RGB-D cameras that capture on a trigger from the tick and deliver frames later.

use crate::error::ErrorType;
use crate::lens::Distortion;
use std::sync::Arc;

/// One image buffer of a frame, shared rather than copied: the recorder and perception hold the
/// same pixels (cloning it clones the pointer). Built from the `Vec` a camera fills, without
/// copying (`Arc::new(vec)`).
pub type SharedPixels<T> = Arc<Vec<T>>;

/// Intrinsics of the colour and depth streams (registered to each other), OpenCV axes and
/// OpenCV's pixel convention: pixel `(u, v)`'s centre is at the integer coordinates `(u, v)`, so
/// the image spans `-0.5 ..= width - 0.5`. A point `(X, Y, Z)` is seen at
/// `(fx xd + cx, fy yd + cy)` where `(xd, yd)` is `(X / Z, Y / Z)` through the lens's
/// [`Distortion`] (none: the pinhole).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// The lens's distortion, as the camera's factory calibration gives it.
    pub distortion: Distortion,
}

impl Intrinsics {
    /// A pinhole (no distortion).
    pub const fn pinhole(width: u32, height: u32, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Intrinsics { width, height, fx, fy, cx, cy, distortion: Distortion::NONE }
    }

    /// These intrinsics with the lens `distortion`.
    pub fn with_distortion(self, distortion: Distortion) -> Self {
        Intrinsics { distortion, ..self }
    }

    /// The intrinsics of the same view resampled to `width` x `height` (edge to edge, as a resize
    /// of the whole image does): the focal lengths scale with the resolution along each axis and
    /// the principal point keeps its place in the image, pixel centres mapping as
    /// `(c + 0.5) * new / old - 0.5` (the pixel convention above). The distortion acts on
    /// normalised coordinates, so it is kept as it is.
    pub fn scaled(&self, width: u32, height: u32) -> Intrinsics {
        let sx = f64::from(width) / f64::from(self.width.max(1));
        let sy = f64::from(height) / f64::from(self.height.max(1));
        Intrinsics {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            distortion: self.distortion,
        }
    }

    /// The pixel at which the point `(x, y, z)` (camera axes, `z > 0`) is seen, through the lens.
    /// Without distortion this is `(fx x / z + cx, fy y / z + cy)` to the bit.
    pub fn project(&self, x: f64, y: f64, z: f64) -> (f64, f64) {
        if self.distortion.is_none() {
            return (self.fx * x / z + self.cx, self.fy * y / z + self.cy);
        }
        let (xd, yd) = self.distortion.distort(x / z, y / z);
        (self.fx * xd + self.cx, self.fy * yd + self.cy)
    }

    /// The ideal normalised coordinates `(X / Z, Y / Z)` of the ray seen at pixel `(u, v)`, the
    /// lens's distortion removed. Without distortion `((u - cx) / fx, (v - cy) / fy)` to the bit.
    pub fn unproject(&self, u: f64, v: f64) -> (f64, f64) {
        let (xd, yd) = ((u - self.cx) / self.fx, (v - self.cy) / self.fy);
        self.distortion.undistort(xd, yd)
    }

    /// The pixel at which the same camera without its lens would see what is at pixel `(u, v)`:
    /// a detected feature's position corrected for the distortion, in pinhole pixels.
    pub fn undistort_pixel(&self, u: f64, v: f64) -> (f64, f64) {
        if self.distortion.is_none() {
            return (u, v);
        }
        let (x, y) = self.unproject(u, v);
        (self.fx * x + self.cx, self.fy * y + self.cy)
    }

    /// These intrinsics without the lens (the same `K`, no distortion).
    pub fn pinhole_part(&self) -> Intrinsics {
        self.with_distortion(Distortion::NONE)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaling_keeps_the_principal_point_where_it_is_in_the_image() {
        // The image centre of 1280x800 is (639.5, 399.5); at half size it is (319.5, 199.5).
        let k = Intrinsics::pinhole(1280, 800, 640.0, 600.0, 639.5, 399.5)
            .with_distortion(Distortion::brown_conrady([0.1, -0.2, 0.001, 0.002, 0.03]));
        let h = k.scaled(640, 400);
        assert_eq!(
            (h.width, h.height, h.fx, h.fy, h.cx, h.cy),
            (640, 400, 320.0, 300.0, 319.5, 199.5)
        );
        assert_eq!(h.distortion, k.distortion);
        // An off-centre point: pixel 0's left edge (-0.5) stays the left edge.
        let o = Intrinsics::pinhole(100, 50, 100.0, 100.0, -0.5, 24.5).scaled(25, 10);
        assert_eq!((o.cx, o.cy), (-0.5, 4.5));
        // The same ray lands on the scaled pixel: (u + 0.5) s - 0.5.
        let (u, v) = k.project(0.2, -0.1, 1.5);
        let (hu, hv) = h.project(0.2, -0.1, 1.5);
        assert!((hu - ((u + 0.5) / 2.0 - 0.5)).abs() < 1e-9, "{u} -> {hu}");
        assert!((hv - ((v + 0.5) / 2.0 - 0.5)).abs() < 1e-9, "{v} -> {hv}");
    }

    #[test]
    fn projection_goes_through_the_lens_and_unprojection_back() {
        let pin = Intrinsics::pinhole(640, 400, 500.0, 500.0, 320.0, 200.0);
        assert_eq!(
            pin.project(0.1, 0.2, 2.0),
            (500.0 * 0.1 / 2.0 + 320.0, 500.0 * 0.2 / 2.0 + 200.0)
        );
        assert_eq!(pin.unproject(345.0, 250.0), (25.0 / 500.0, 50.0 / 500.0));
        assert_eq!(pin.undistort_pixel(1.0, 2.0), (1.0, 2.0));
        let k = pin.with_distortion(Distortion::brown_conrady([-0.3, 0.1, 0.0, 0.0, 0.0]));
        // Barrel distortion pulls an off-axis point towards the centre.
        let (u, v) = k.project(0.3, 0.2, 1.0);
        let (pu, pv) = pin.project(0.3, 0.2, 1.0);
        assert!(u < pu - 5.0 && v < pv - 3.0, "({u}, {v}) vs ({pu}, {pv})");
        let (x, y) = k.unproject(u, v);
        assert!((x - 0.3).abs() < 1e-10 && (y - 0.2).abs() < 1e-10, "({x}, {y})");
        let (iu, iv) = k.undistort_pixel(u, v);
        assert!((iu - pu).abs() < 1e-7 && (iv - pv).abs() < 1e-7);
    }
}
