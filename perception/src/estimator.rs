//! The one trait every pose-estimation backend implements, its answer, and backend selection.

use crate::icp::{IcpConfig, IcpTracker};
use crate::models::Mesh;
use crate::{PerceptionError, PerceptionFrame};
use hitl_hal::Pose;
use std::path::PathBuf;

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

/// A parsed `--perception` / `--backend` value.
#[derive(Debug, Clone, PartialEq)]
pub enum BackendSpec {
    None,
    Icp,
    /// The monocular baseline ([`crate::mono`]): colour and mask, no depth.
    Mono,
    Onnx(PathBuf),
    Socket(PathBuf),
}

impl std::str::FromStr for BackendSpec {
    type Err = PerceptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => Ok(BackendSpec::None),
            "icp" => Ok(BackendSpec::Icp),
            "mono" => Ok(BackendSpec::Mono),
            _ => {
                if let Some(p) = s.strip_prefix("onnx:").filter(|p| !p.is_empty()) {
                    Ok(BackendSpec::Onnx(PathBuf::from(p)))
                } else if let Some(p) = s.strip_prefix("socket:").filter(|p| !p.is_empty()) {
                    Ok(BackendSpec::Socket(PathBuf::from(p)))
                } else {
                    Err(PerceptionError::UnknownBackend(s.to_string()))
                }
            }
        }
    }
}

/// Builds the backend a spec names. `mesh` is the target model at the scale the camera sees it
/// (lab metres); the ICP tracker, the monocular baseline, mask-output ONNX models and the external estimator
/// (which receives it in its handshake) need it. `None` gives `Ok(None)`.
pub fn backend_from_spec(
    spec: &BackendSpec,
    mesh: &Mesh,
) -> Result<Option<Box<dyn PoseEstimator>>, PerceptionError> {
    Ok(match spec {
        BackendSpec::None => None,
        BackendSpec::Icp => Some(Box::new(IcpTracker::new(mesh, IcpConfig::default())?)),
        BackendSpec::Mono => {
            Some(Box::new(crate::mono::MonoTracker::new(mesh, crate::mono::MonoConfig::default())?))
        }
        BackendSpec::Onnx(path) => {
            Some(Box::new(crate::onnx::OnnxEstimator::load(path, Some(mesh))?))
        }
        BackendSpec::Socket(path) => {
            Some(Box::new(crate::socket::SocketEstimator::connect(path, mesh)?))
        }
    })
}
