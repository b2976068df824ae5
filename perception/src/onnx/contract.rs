//! Checking a model's inputs and outputs against the contract (see the parent module).

use ort::session::Session;
use ort::value::{TensorElementType, ValueType};

/// A recognised model input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    Rgb,
    Depth,
    Mask,
    Intrinsics,
}

/// The output the estimator uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    Pose4x4,
    PoseQuat,
    /// `count` when the model fixes K.
    Keypoints {
        count: Option<usize>,
    },
    Mask,
}

/// What a checked model takes and gives.
#[derive(Debug, Clone, PartialEq)]
pub struct Contract {
    pub inputs: Vec<InputKind>,
    /// Image (height, width) when the model fixes it.
    pub image_hw: Option<(usize, usize)>,
    pub output: OutputKind,
    pub has_scores: bool,
}

fn float_shape(name: &str, t: &ValueType) -> Result<Vec<i64>, String> {
    match t {
        ValueType::Tensor { ty, shape, .. } => {
            if *ty != TensorElementType::Float32 {
                return Err(format!("tensor {name:?} is {ty:?}, the contract wants float32"));
            }
            Ok(shape.iter().copied().collect())
        }
        other => Err(format!("{name:?} is {other:?}, the contract wants a float32 tensor")),
    }
}

/// A dimension that must be `want` (or dynamic).
fn dim_ok(d: i64, want: i64) -> bool {
    d < 0 || d == want
}

fn shape_str(s: &[i64]) -> String {
    let v: Vec<String> =
        s.iter().map(|d| if *d < 0 { "?".into() } else { d.to_string() }).collect();
    format!("[{}]", v.join(","))
}

impl Contract {
    /// Checks a loaded session; the error names the offending tensor.
    pub fn from_session(s: &Session) -> Result<Contract, String> {
        let mut inputs = Vec::new();
        let mut hw: Option<(i64, i64)> = None;
        for i in s.inputs() {
            let name = i.name();
            let shape = float_shape(name, i.dtype())?;
            let (kind, channels) = match name {
                "rgb" => (InputKind::Rgb, 3),
                "depth" => (InputKind::Depth, 1),
                "mask" => (InputKind::Mask, 1),
                "intrinsics" => {
                    if shape.len() != 3
                        || !dim_ok(shape[0], 1)
                        || !dim_ok(shape[1], 3)
                        || !dim_ok(shape[2], 3)
                    {
                        return Err(format!(
                            "input \"intrinsics\" has shape {}, expected [1,3,3]",
                            shape_str(&shape)
                        ));
                    }
                    inputs.push(InputKind::Intrinsics);
                    continue;
                }
                other => {
                    return Err(format!(
                        "unknown input {other:?} (the contract knows rgb, depth, mask, intrinsics)"
                    ))
                }
            };
            if shape.len() != 4 || !dim_ok(shape[0], 1) || !dim_ok(shape[1], channels) {
                return Err(format!(
                    "input {name:?} has shape {}, expected [1,{channels},H,W]",
                    shape_str(&shape)
                ));
            }
            let this = (shape[2], shape[3]);
            if let Some(prev) = hw {
                if (prev.0 >= 0 && this.0 >= 0 && prev.0 != this.0)
                    || (prev.1 >= 0 && this.1 >= 0 && prev.1 != this.1)
                {
                    return Err(format!("input {name:?} disagrees with the other images on H x W"));
                }
            }
            if hw.is_none() || this.0 >= 0 {
                hw = Some(this);
            }
            inputs.push(kind);
        }
        if !inputs.iter().any(|k| matches!(k, InputKind::Rgb | InputKind::Depth)) {
            return Err("needs an \"rgb\" or a \"depth\" input".into());
        }
        let outs: Vec<(&str, Vec<i64>)> = s
            .outputs()
            .iter()
            .filter(|o| matches!(o.name(), "pose" | "keypoints" | "mask" | "scores"))
            .map(|o| float_shape(o.name(), o.dtype()).map(|sh| (o.name(), sh)))
            .collect::<Result<_, _>>()?;
        let find = |n: &str| outs.iter().find(|(name, _)| *name == n).map(|(_, s)| s.clone());
        let output = if let Some(sh) = find("pose") {
            let last = sh.last().copied().unwrap_or(0);
            if sh.len() == 3 && dim_ok(sh[0], 1) && sh[1] == 4 && sh[2] == 4 {
                OutputKind::Pose4x4
            } else if sh.len() == 2 && dim_ok(sh[0], 1) && last == 7 {
                OutputKind::PoseQuat
            } else {
                return Err(format!(
                    "output \"pose\" has shape {}, expected [1,4,4] or [1,7]",
                    shape_str(&sh)
                ));
            }
        } else if let Some(sh) = find("keypoints") {
            if sh.len() != 3 || !dim_ok(sh[0], 1) || sh[2] != 2 {
                return Err(format!(
                    "output \"keypoints\" has shape {}, expected [1,K,2]",
                    shape_str(&sh)
                ));
            }
            OutputKind::Keypoints { count: (sh[1] >= 0).then_some(sh[1] as usize) }
        } else if let Some(sh) = find("mask") {
            if sh.len() != 4 || !dim_ok(sh[0], 1) || !dim_ok(sh[1], 1) {
                return Err(format!(
                    "output \"mask\" has shape {}, expected [1,1,H,W]",
                    shape_str(&sh)
                ));
            }
            OutputKind::Mask
        } else {
            let names: Vec<&str> = s.outputs().iter().map(|o| o.name()).collect();
            return Err(format!(
                "no recognised output (needs \"pose\", \"keypoints\" or \"mask\"; the model has {names:?})"
            ));
        };
        let has_scores = matches!(output, OutputKind::Keypoints { .. }) && find("scores").is_some();
        let image_hw = hw.and_then(|(h, w)| (h >= 0 && w >= 0).then_some((h as usize, w as usize)));
        Ok(Contract { inputs, image_hw, output, has_scores })
    }
}
