//! `hitl-perception`: the pose-estimation side of the testbed.
//!
//! Every captured frame goes to an asynchronous [`worker`] that runs one [`PoseEstimator`]
//! backend (the built-in model-based [`icp`] tracker, the [`mono`] colour baseline, or an
//! [`onnx`] model) and emits a
//! target-in-camera pose stamped with the frame's timestamp. [`metrics`] scores estimates against
//! ground truth exactly as the DreamSat-Bench paper does; [`normalize`] is the paper's depth
//! normalisation; [`models`] holds the target meshes (procedural spacecraft and the user's
//! OBJ/STL). All poses are 4x4 rigid transforms from the target (model) frame to the camera frame,
//! OpenCV camera axes (x right, y down, z forward), metres of the scene the camera sees.

pub mod backends;
pub mod bench;
pub mod bound;
pub mod error;
pub mod estimator;
pub mod frame;
pub mod icp;
pub mod metrics;
pub mod models;
#[cfg(feature = "mono")]
pub mod mono;
pub mod normalize;
#[cfg(feature = "onnx")]
pub mod onnx;
pub mod pnp;
pub mod pose;
pub mod replay;
pub mod reregister;
pub mod silhouette;
pub mod socket;
pub mod testing;
pub mod tracker_bench;
pub mod undistort;
pub mod worker;

pub use backends::{backend_from_spec, BackendSpec};
pub use error::PerceptionError;
pub use estimator::{Estimate, EstimateKind, PoseEstimator};
pub use frame::PerceptionFrame;
pub use metrics::{evaluate, FrameError, Metrics, PosePair};
pub use models::{Mesh, SymmetryClass, TargetModel};
pub use reregister::{PolicyError, ReregisterPolicy, Reregistering};
pub use worker::{spawn_worker, PoseResult, WorkerHandle, WorkerStats};
