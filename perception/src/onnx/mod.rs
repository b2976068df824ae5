//! `onnx:MODEL`: pose estimation by an ONNX model through ONNX Runtime (`ort`, load-dynamic).

use crate::estimator::{Estimate, PoseEstimator};
use crate::models::Mesh;
use crate::{PerceptionError, PerceptionFrame};
use std::path::Path;

pub struct OnnxEstimator;

impl OnnxEstimator {
    pub fn load(path: &Path, _mesh: Option<&Mesh>) -> Result<OnnxEstimator, PerceptionError> {
        Err(PerceptionError::OnnxContract { path: path.to_path_buf(), reason: "not built".into() })
    }
}

impl PoseEstimator for OnnxEstimator {
    fn name(&self) -> String {
        "onnx".into()
    }
    fn estimate(&mut self, _frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        Ok(Estimate::lost())
    }
    fn reset(&mut self) {}
}
