//! The backend registry: the `--perception` / `--backend` values ([`BackendSpec`]) and the one
//! place that builds the backend a value names ([`backend_from_spec`]). A new backend adds its
//! module, a variant here and its arm in `backend_from_spec`; the trait's module
//! ([`crate::estimator`]) does not change.

use crate::estimator::PoseEstimator;
use crate::icp::{IcpConfig, IcpTracker};
use crate::models::{Mesh, Symmetry};
use crate::PerceptionError;
use std::path::PathBuf;

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
/// (which receives it in its handshake) need it. `symmetry` is the target's declared symmetry at
/// the same scale ([`crate::TargetModel::symmetry_group`] scaled to the lab), which the ICP
/// tracker keeps its branch by. `None` gives `Ok(None)`.
pub fn backend_from_spec(
    spec: &BackendSpec,
    mesh: &Mesh,
    symmetry: &Symmetry,
) -> Result<Option<Box<dyn PoseEstimator>>, PerceptionError> {
    Ok(match spec {
        BackendSpec::None => None,
        BackendSpec::Icp => {
            Some(Box::new(IcpTracker::new(mesh, IcpConfig::default())?.with_symmetry(symmetry)))
        }
        #[cfg(feature = "mono")]
        BackendSpec::Mono => {
            Some(Box::new(crate::mono::MonoTracker::new(mesh, crate::mono::MonoConfig::default())?))
        }
        #[cfg(feature = "onnx")]
        BackendSpec::Onnx(path) => {
            Some(Box::new(crate::onnx::OnnxEstimator::load(path, Some(mesh))?))
        }
        #[cfg(not(feature = "mono"))]
        BackendSpec::Mono => {
            return Err(PerceptionError::NotBuilt { backend: "mono", feature: "mono" })
        }
        #[cfg(not(feature = "onnx"))]
        BackendSpec::Onnx(_) => {
            return Err(PerceptionError::NotBuilt { backend: "onnx", feature: "onnx" })
        }
        BackendSpec::Socket(path) => {
            Some(Box::new(crate::socket::SocketEstimator::connect(path, mesh)?))
        }
    })
}
