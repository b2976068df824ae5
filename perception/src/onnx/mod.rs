//! `onnx:MODEL`: pose estimation by an ONNX model through ONNX Runtime (`ort`, load-dynamic).
//!
//! The contract (docs/perception.md): float32 inputs by name, any non-empty subset of
//! `rgb` [1,3,H,W] in 0..1, `depth` [1,1,H,W] metres (0 = no return), `mask` [1,1,H,W] 0/1,
//! `intrinsics` [1,3,3]; H and W fixed by the model or dynamic (then the frame's size). One
//! recognised output, in this order of preference:
//! - `pose` [1,4,4] (target in camera, OpenCV axes, metres) or [1,7] (qw qx qy qz tx ty tz);
//! - `keypoints` [1,K,2] pixels, solved by PnP against K body-frame points read from
//!   `MODEL.keypoints.json` (`{"points": [[x, y, z], ...]}`, metres as the camera sees the target);
//!   an optional `scores` [1,K] output drops keypoints scoring below 0.5;
//! - `mask` [1,1,H,W] target probability: thresholded at 0.5 and handed with the frame's depth to
//!   the built-in ICP tracker (needs the target mesh).
//!
//! The model is checked against this at load; every violation is an error naming the tensor.

mod contract;
mod runtime;

pub use contract::{Contract, InputKind, OutputKind};
pub use runtime::{dylib_path, environment};

use crate::estimator::{Estimate, EstimateKind, PoseEstimator};
use crate::icp::{IcpConfig, IcpTracker};
use crate::models::Mesh;
use crate::{pnp, PerceptionError, PerceptionFrame};
use hitl_hal::pose::{self, Pose};
use nalgebra::{Matrix4, Vector3};
use ort::session::{Session, SessionInputValue};
use ort::value::Tensor;
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// An ONNX model behind the [`PoseEstimator`] trait.
pub struct OnnxEstimator {
    path: PathBuf,
    session: Session,
    contract: Contract,
    /// Body-frame keypoints for a `keypoints` model.
    keypoints_body: Vec<Vector3<f64>>,
    /// Tracker fed by a `mask` model.
    tracker: Option<IcpTracker>,
}

fn rt_err(path: &Path) -> impl Fn(String) -> PerceptionError + '_ {
    move |e| PerceptionError::OnnxRuntime(format!("{}: {e}", path.display()))
}

impl OnnxEstimator {
    /// Loads and checks a model. `mesh` (lab metres) is needed only by `mask` models.
    pub fn load(path: &Path, mesh: Option<&Mesh>) -> Result<OnnxEstimator, PerceptionError> {
        let bad =
            |reason: String| PerceptionError::OnnxContract { path: path.to_path_buf(), reason };
        if !path.is_file() {
            return Err(bad("no such file".into()));
        }
        let env = runtime::environment()?;
        let session = Session::builder(&env)
            .map_err(|e| e.to_string())
            .and_then(|b| b.with_intra_threads(1).map_err(|e| e.to_string()))
            .and_then(|mut b| b.commit_from_file(path).map_err(|e| e.to_string()))
            .map_err(|e| bad(format!("ONNX Runtime cannot load it: {e}")))?;
        let contract = Contract::from_session(&session).map_err(bad)?;
        let mut keypoints_body = Vec::new();
        let mut tracker = None;
        match contract.output {
            OutputKind::Keypoints { count } => {
                keypoints_body = read_keypoints(path)?;
                if let Some(k) = count {
                    if k != keypoints_body.len() {
                        return Err(bad(format!(
                            "outputs {k} keypoints but the sidecar lists {} points",
                            keypoints_body.len()
                        )));
                    }
                }
            }
            OutputKind::Mask => {
                let mesh = mesh.ok_or_else(|| {
                    bad("a mask model needs the target mesh for the ICP tracker".into())
                })?;
                tracker = Some(IcpTracker::new(mesh, IcpConfig::default())?);
            }
            _ => {}
        }
        Ok(OnnxEstimator { path: path.to_path_buf(), session, contract, keypoints_body, tracker })
    }

    pub fn contract(&self) -> &Contract {
        &self.contract
    }

    fn inputs(
        &self,
        frame: &PerceptionFrame,
    ) -> Result<Vec<(Cow<'static, str>, SessionInputValue<'static>)>, PerceptionError> {
        let (w, h) = (frame.intrinsics.width as usize, frame.intrinsics.height as usize);
        if let Some((mh, mw)) = self.contract.image_hw {
            if (mh, mw) != (h, w) {
                return Err(PerceptionError::BadFrame(format!(
                    "model {} takes {mw}x{mh} images, frame is {w}x{h}",
                    self.path.display()
                )));
            }
        }
        let n = w * h;
        let err = rt_err(&self.path);
        let mut out = Vec::new();
        for kind in &self.contract.inputs {
            let (name, value): (&'static str, Tensor<f32>) = match kind {
                InputKind::Rgb => {
                    if frame.color.len() != 3 * n {
                        return Err(PerceptionError::BadFrame(
                            "the model needs colour, the frame has none".into(),
                        ));
                    }
                    let mut planar = vec![0f32; 3 * n];
                    for i in 0..n {
                        for c in 0..3 {
                            planar[c * n + i] = frame.color[3 * i + c] as f32 / 255.0;
                        }
                    }
                    (
                        "rgb",
                        Tensor::from_array(([1usize, 3, h, w], planar))
                            .map_err(|e| err(e.to_string()))?,
                    )
                }
                InputKind::Depth => {
                    let d: Vec<f32> = frame
                        .depth_m
                        .iter()
                        .map(|d| if d.is_finite() && *d > 0.0 { *d } else { 0.0 })
                        .collect();
                    (
                        "depth",
                        Tensor::from_array(([1usize, 1, h, w], d))
                            .map_err(|e| err(e.to_string()))?,
                    )
                }
                InputKind::Mask => {
                    let m = frame.mask.as_ref().ok_or_else(|| {
                        PerceptionError::BadFrame(
                            "the model needs a mask, the frame has none".into(),
                        )
                    })?;
                    let m: Vec<f32> = m.iter().map(|&v| if v != 0 { 1.0 } else { 0.0 }).collect();
                    (
                        "mask",
                        Tensor::from_array(([1usize, 1, h, w], m))
                            .map_err(|e| err(e.to_string()))?,
                    )
                }
                InputKind::Intrinsics => {
                    let k = &frame.intrinsics;
                    let m = vec![
                        k.fx as f32,
                        0.0,
                        k.cx as f32,
                        0.0,
                        k.fy as f32,
                        k.cy as f32,
                        0.0,
                        0.0,
                        1.0,
                    ];
                    (
                        "intrinsics",
                        Tensor::from_array(([1usize, 3, 3], m)).map_err(|e| err(e.to_string()))?,
                    )
                }
            };
            out.push((Cow::Borrowed(name), SessionInputValue::from(value)));
        }
        Ok(out)
    }
}

fn read_keypoints(model: &Path) -> Result<Vec<Vector3<f64>>, PerceptionError> {
    let side = model.with_extension("keypoints.json");
    let bad = |reason: String| PerceptionError::OnnxContract { path: side.clone(), reason };
    let meta = std::fs::metadata(&side)
        .map_err(|e| bad(format!("a keypoints model needs this sidecar file: {e}")))?;
    if meta.len() > 1 << 20 {
        return Err(bad("larger than 1 MiB".into()));
    }
    let text = std::fs::read_to_string(&side).map_err(|e| bad(e.to_string()))?;
    #[derive(serde::Deserialize)]
    struct Side {
        points: Vec<[f64; 3]>,
    }
    let s: Side = serde_json::from_str(&text)
        .map_err(|e| bad(format!("not {{\"points\": [[x,y,z],...]}}: {e}")))?;
    if s.points.len() < 6 {
        return Err(bad(format!("PnP needs at least 6 points, has {}", s.points.len())));
    }
    if s.points.iter().flatten().any(|v| !v.is_finite()) {
        return Err(bad("a point is not finite".into()));
    }
    Ok(s.points.iter().map(|p| Vector3::new(p[0], p[1], p[2])).collect())
}

impl PoseEstimator for OnnxEstimator {
    fn name(&self) -> String {
        format!("onnx:{}", self.path.display())
    }

    fn estimate(&mut self, frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        frame.validate()?;
        let inputs = self.inputs(frame)?;
        let err = rt_err(&self.path);
        let outputs = self.session.run(inputs).map_err(|e| err(e.to_string()))?;
        // A matrix that is not rigid (or not finite), or a quaternion of no length, is `Lost`.
        let direct = |p: Option<Pose>| match p {
            Some(p) => Estimate { pose: Some(p), kind: EstimateKind::Direct, residual_m: 0.0 },
            None => Estimate::lost(),
        };
        match self.contract.output {
            OutputKind::Pose4x4 | OutputKind::PoseQuat => {
                let (_, v) =
                    outputs["pose"].try_extract_tensor::<f32>().map_err(|e| err(e.to_string()))?;
                let v: Vec<f64> = v.iter().map(|&x| x as f64).collect();
                let p = if v.len() == 16 {
                    pose::from_matrix_checked(&Matrix4::from_row_slice(&v))
                } else if v.len() == 7 {
                    // The contract's order is qw qx qy qz tx ty tz.
                    pose::from_quat_xyzw_t([v[1], v[2], v[3], v[0]], [v[4], v[5], v[6]])
                } else {
                    return Err(err(format!(
                        "pose output has {} values, expected 16 or 7",
                        v.len()
                    )));
                };
                Ok(direct(p))
            }
            OutputKind::Keypoints { .. } => {
                let (_, kp) = outputs["keypoints"]
                    .try_extract_tensor::<f32>()
                    .map_err(|e| err(e.to_string()))?;
                if kp.len() != 2 * self.keypoints_body.len() {
                    return Err(err(format!(
                        "keypoints output has {} values, expected {}",
                        kp.len(),
                        2 * self.keypoints_body.len()
                    )));
                }
                let scores: Option<Vec<f32>> = if self.contract.has_scores {
                    let (_, s) = outputs["scores"]
                        .try_extract_tensor::<f32>()
                        .map_err(|e| err(e.to_string()))?;
                    Some(s.to_vec())
                } else {
                    None
                };
                let mut body = Vec::new();
                let mut px = Vec::new();
                for (i, p) in self.keypoints_body.iter().enumerate() {
                    if scores.as_ref().is_some_and(|s| s.get(i).is_none_or(|&v| v < 0.5)) {
                        continue;
                    }
                    body.push(*p);
                    px.push((kp[2 * i] as f64, kp[2 * i + 1] as f64));
                }
                match pnp::solve_pnp(&body, &px, &frame.intrinsics) {
                    Ok(p) => Ok(direct(Some(p).filter(pose::is_rigid))),
                    Err(_) => Ok(Estimate::lost()),
                }
            }
            OutputKind::Mask => {
                let (_, m) =
                    outputs["mask"].try_extract_tensor::<f32>().map_err(|e| err(e.to_string()))?;
                if m.len() != frame.depth_m.len() {
                    return Err(err(format!(
                        "mask output has {} values, frame has {} pixels",
                        m.len(),
                        frame.depth_m.len()
                    )));
                }
                let mut masked = frame.clone();
                masked.mask = Some(
                    m.iter().map(|&v| if v >= 0.5 { 255 } else { 0 }).collect::<Vec<_>>().into(),
                );
                drop(outputs);
                match self.tracker.as_mut() {
                    Some(t) => t.estimate(&masked),
                    None => Ok(Estimate::lost()),
                }
            }
        }
    }

    fn reset(&mut self) {
        if let Some(t) = self.tracker.as_mut() {
            t.reset();
        }
    }
}
