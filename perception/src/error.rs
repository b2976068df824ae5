//! The one error type of the crate: every message names the problem (file, field, expected shape).

use std::path::PathBuf;

/// Why perception could not do what it was asked (never "the pose is bad": that is an
/// [`crate::Estimate`] of kind `Lost`).
#[derive(Debug, thiserror::Error)]
pub enum PerceptionError {
    /// A frame whose buffers do not match its intrinsics, or with no usable depth.
    #[error("bad frame: {0}")]
    BadFrame(String),
    /// A mesh file that cannot be used as a target model.
    #[error("target model {path}: {reason}")]
    BadModel { path: PathBuf, reason: String },
    /// A mesh that is empty or degenerate.
    #[error("target mesh: {0}")]
    BadMesh(String),
    /// An ONNX model that breaks the input/output contract (docs/perception.md).
    #[error("onnx model {path}: {reason}")]
    OnnxContract { path: PathBuf, reason: String },
    /// ONNX Runtime could not be loaded or failed while running.
    #[error("onnx runtime: {0}")]
    OnnxRuntime(String),
    /// A backend this build left out (`make demo` builds only what the demo runs).
    #[error(
        "perception backend {backend} is not in this build (built without the `{feature}` \
         feature; `cargo build --release` builds every backend)"
    )]
    NotBuilt { backend: &'static str, feature: &'static str },
    /// A backend name the CLI does not know.
    #[error(
        "unknown perception backend {0:?} (expected icp, mono, onnx:MODEL.onnx, socket:PATH or none)"
    )]
    UnknownBackend(String),
    /// Bad numbers handed to a metric or solver (NaN, not a rotation, too few points).
    #[error("bad input: {0}")]
    BadInput(String),
    /// The external estimator's socket failed or spoke out of protocol.
    #[error("external estimator: {0}")]
    External(String),
}
