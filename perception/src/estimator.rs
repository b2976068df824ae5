//! The one trait every pose-estimation backend implements, and its answer. It names no backend:
//! choosing one by name is [`crate::backends`].

use crate::{PerceptionError, PerceptionFrame};
use hitl_hal::Pose;

/// How an estimate came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EstimateKind {
    /// Global registration ran on this frame (first frame, after a reset or a lost track).
    Registered,
    /// Frame-to-frame tracking from the previous pose.
    Tracked,
    /// A single-shot estimate (model backends with no tracking state).
    Direct,
    /// No pose: the estimator failed on this frame (counted as a failure by the metrics).
    Lost,
}

/// A backend's answer for one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Target in camera (OpenCV axes, metres); `None` when `kind == Lost`.
    pub pose: Option<Pose>,
    pub kind: EstimateKind,
    /// Backend-specific fit residual in metres (ICP: RMS point-to-plane distance of inliers;
    /// 0 when the backend has none).
    pub residual_m: f64,
}

impl Estimate {
    pub fn lost() -> Self {
        Estimate { pose: None, kind: EstimateKind::Lost, residual_m: f64::NAN }
    }
}

/// A pose-estimation backend. Implementations keep tracking state between frames.
pub trait PoseEstimator: Send {
    /// Short name for logs and recordings.
    fn name(&self) -> String;
    /// Estimates the target pose in this frame. `Err` only for bad input or a broken backend;
    /// a lost track is `Ok` with `EstimateKind::Lost`.
    fn estimate(&mut self, frame: &PerceptionFrame) -> Result<Estimate, PerceptionError>;
    /// Forgets the tracking state: the next frame starts with global registration.
    fn reset(&mut self);
}

/// An estimator whose scene units can be rescaled (for [`crate::normalize::DepthNormalized`]).
pub trait ScalableEstimator: PoseEstimator {
    /// The scene (depth and mesh) is now `factor` times what it was: scale the mesh and any
    /// remembered translation by `factor`.
    fn rescale_scene(&mut self, factor: f64);
}
