//! `socket:PATH`: an external estimator over a local unix socket (e.g. FoundationPose on a GPU
//! box). Not built yet: connecting reports that.

use crate::estimator::{Estimate, PoseEstimator};
use crate::{PerceptionError, PerceptionFrame};
use std::path::Path;

/// Placeholder for the external estimator client.
pub struct SocketEstimator;

impl SocketEstimator {
    pub fn connect(path: &Path) -> Result<SocketEstimator, PerceptionError> {
        Err(PerceptionError::External(format!(
            "{}: the external-estimator backend is not built yet",
            path.display()
        )))
    }
}

impl PoseEstimator for SocketEstimator {
    fn name(&self) -> String {
        "socket".into()
    }
    fn estimate(&mut self, _frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        Err(PerceptionError::External("not connected".into()))
    }
    fn reset(&mut self) {}
}
