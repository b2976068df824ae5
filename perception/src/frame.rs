//! What a backend sees of one capture: colour, depth (metres), optional mask, intrinsics, stamp.

use crate::PerceptionError;
use hitl_hal::{Intrinsics, RgbdFrame, SharedPixels};
use std::sync::Arc;

/// One frame handed to a pose estimator. Its pixels are the camera frame's own, shared with the
/// recorder ([`SharedPixels`]), not copied.
#[derive(Debug, Clone, PartialEq)]
pub struct PerceptionFrame {
    /// Capture timestamp (host monotonic ns); the estimate carries it back unchanged.
    pub timestamp_ns: u64,
    /// Sequence number of the capture (tick or frame index), for logs and results.
    pub seq: u64,
    pub intrinsics: Intrinsics,
    /// rgb8, row-major, `width * height * 3` bytes (may be empty for depth-only backends).
    pub color: SharedPixels<u8>,
    /// Depth in metres, row-major, 0 (or non-finite) where there is no return.
    pub depth_m: SharedPixels<f32>,
    /// Target mask, 0 = background, anything else = target.
    pub mask: Option<SharedPixels<u8>>,
}

impl PerceptionFrame {
    /// Checks buffer sizes against the intrinsics.
    pub fn validate(&self) -> Result<(), PerceptionError> {
        let i = &self.intrinsics;
        let n = i.width as usize * i.height as usize;
        if n == 0 {
            return Err(PerceptionError::BadFrame("zero-sized image".into()));
        }
        if !(i.fx > 0.0 && i.fy > 0.0 && i.cx.is_finite() && i.cy.is_finite()) {
            return Err(PerceptionError::BadFrame(format!(
                "bad intrinsics fx={} fy={} cx={} cy={}",
                i.fx, i.fy, i.cx, i.cy
            )));
        }
        if self.depth_m.len() != n {
            return Err(PerceptionError::BadFrame(format!(
                "depth has {} pixels, intrinsics say {}x{}",
                self.depth_m.len(),
                i.width,
                i.height
            )));
        }
        if !self.color.is_empty() && self.color.len() != n * 3 {
            return Err(PerceptionError::BadFrame(format!(
                "colour has {} bytes, expected {} (rgb8 {}x{})",
                self.color.len(),
                n * 3,
                i.width,
                i.height
            )));
        }
        if let Some(m) = &self.mask {
            if m.len() != n {
                return Err(PerceptionError::BadFrame(format!(
                    "mask has {} pixels, expected {n}",
                    m.len()
                )));
            }
        }
        Ok(())
    }

    /// True if pixel `idx` lies in the target's silhouette: in the mask if there is one (with or
    /// without depth: a stereo camera has none at edges and in shadows), else any valid depth.
    pub fn in_silhouette(&self, idx: usize) -> bool {
        match &self.mask {
            Some(m) => m[idx] != 0,
            None => {
                let d = self.depth_m[idx];
                d.is_finite() && d > 0.0
            }
        }
    }

    /// True if pixel `idx` belongs to the target (by mask if there is one, else any valid depth).
    pub fn is_target(&self, idx: usize) -> bool {
        let d = self.depth_m[idx];
        let has_depth = d.is_finite() && d > 0.0;
        match &self.mask {
            Some(m) => has_depth && m[idx] != 0,
            None => has_depth,
        }
    }
}

impl From<&RgbdFrame> for PerceptionFrame {
    fn from(f: &RgbdFrame) -> Self {
        PerceptionFrame {
            timestamp_ns: f.exposure_ns,
            seq: f.request.tick,
            intrinsics: f.intrinsics,
            color: Arc::clone(&f.color),
            depth_m: Arc::clone(&f.depth_m),
            mask: f.mask.clone(),
        }
    }
}
