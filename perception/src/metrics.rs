//! The paper's tracking-error metrics (DreamSat-Bench, "Evaluation Metrics").
//!
//! On the reference frame (the first frame, see below) the calibration offset
//! `dT = inv(T0_est) * T0_gt` is computed; every frame's estimate is corrected as
//! `T_k_corr = T_k_est * dT` and compared with ground truth:
//! `e_t = |t_corr - t_gt|` (converted to real metres by dividing the scene's lab metres by the
//! run's `scale`, real = lab / scale) and `e_r = |log(R_corr^T R_gt)|` in degrees.
//!
//! Failures: a frame counts as a failure when the estimator gave no pose, a non-rigid or
//! non-finite matrix, or the identity matrix (the paper's estimator signals a lost track with
//! the identity). Failed frames are counted and left out of mean/median/std. The reference frame
//! is the first frame with a usable estimate; frames before it are failures. Statistics use the
//! population standard deviation (numpy's default, ddof = 0).
//!
//! Next to the paper's figures, [`evaluate_symmetric`] scores the same corrected estimates up to
//! the target's declared symmetry ([`Symmetry`]): `e_r_sym = min over S of |log(R_corr^T R_gt
//! R_S)|` and `e_t_sym` against that same twin `T_gt * S`. The paper's `e_t` and `e_r` are
//! computed exactly as before; the symmetric ones are never above `e_r` (the identity is in every
//! group) and equal the paper's when the target declares no symmetry.

use crate::models::Symmetry;
use crate::PerceptionError;
use hitl_hal::pose::{self, Pose};
use serde::Serialize;

/// Ground truth and the estimator's answer for one frame (both target-in-camera, lab metres).
#[derive(Debug, Clone, PartialEq)]
pub struct PosePair {
    pub timestamp_ns: u64,
    pub gt: Pose,
    /// `None` when the estimator produced nothing for this frame.
    pub est: Option<Pose>,
}

/// Error of one scored frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameError {
    pub timestamp_ns: u64,
    /// Translation error, real metres.
    pub et_m: f64,
    /// Rotation error, degrees.
    pub er_deg: f64,
    /// Translation error against the nearest symmetric twin of the ground truth, real metres.
    pub et_sym_m: f64,
    /// Rotation error up to the target's symmetry, degrees (<= `er_deg`).
    pub er_sym_deg: f64,
}

/// Summary over a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Metrics {
    /// Frames with ground truth.
    pub frames: usize,
    /// Frames scored (frames - failures).
    pub scored: usize,
    pub failures: usize,
    /// Lab metres per real metre used for e_t.
    pub scale: f64,
    pub mean_et_m: f64,
    pub median_et_m: f64,
    pub std_et_m: f64,
    pub mean_er_deg: f64,
    pub median_er_deg: f64,
    pub std_er_deg: f64,
    /// The symmetry the `_sym` figures are taken up to ([`Symmetry::spec`]).
    pub symmetry: String,
    pub mean_et_sym_m: f64,
    pub median_et_sym_m: f64,
    pub std_et_sym_m: f64,
    pub mean_er_sym_deg: f64,
    pub median_er_sym_deg: f64,
    pub std_er_sym_deg: f64,
    /// Timestamp of the reference (calibration) frame, if any frame could be scored.
    pub reference_timestamp_ns: Option<u64>,
    #[serde(skip)]
    pub per_frame: Vec<FrameError>,
}

/// True if the estimate is a usable pose (finite, rigid, not the identity failure signal).
pub fn is_valid_estimate(t: &Pose) -> bool {
    pose::is_rigid(t) && *t != Pose::identity()
}

/// Translation (real metres) and rotation (degrees) error of a corrected estimate.
pub fn frame_error(corr: &Pose, gt: &Pose, scale: f64) -> (f64, f64) {
    let (et_lab, er) = pose::difference(corr, gt);
    (et_lab / scale, er.to_degrees())
}

/// Scores a run. `pairs` must be in capture order; `scale` = lab metres per real metre (> 0).
/// The `_sym` figures equal the paper's (no symmetry declared).
pub fn evaluate(pairs: &[PosePair], scale: f64) -> Result<Metrics, PerceptionError> {
    evaluate_symmetric(pairs, scale, &Symmetry::none())
}

/// [`evaluate`], with the `_sym` figures taken up to `symmetry` (body frame, real metres: its
/// point is scaled to the lab with `scale`).
pub fn evaluate_symmetric(
    pairs: &[PosePair],
    scale: f64,
    symmetry: &Symmetry,
) -> Result<Metrics, PerceptionError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(PerceptionError::BadInput(format!(
            "scale must be a positive number, got {scale}"
        )));
    }
    for p in pairs {
        if !pose::is_rigid(&p.gt) {
            return Err(PerceptionError::BadInput(format!(
                "ground-truth pose at t={} ns is not a rigid transform",
                p.timestamp_ns
            )));
        }
    }
    let lab_symmetry = symmetry.clone().transformed([0.0; 3], scale);
    let mut dt: Option<Pose> = None;
    let mut reference = None;
    let mut per_frame = Vec::with_capacity(pairs.len());
    let mut failures = 0;
    for p in pairs {
        let est = match &p.est {
            Some(e) if is_valid_estimate(e) => e,
            _ => {
                failures += 1;
                continue;
            }
        };
        let offset = *dt.get_or_insert_with(|| {
            reference = Some(p.timestamp_ns);
            est.inverse() * p.gt
        });
        let corr = est * offset;
        let (et_m, er_deg) = frame_error(&corr, &p.gt, scale);
        let sym = lab_symmetry.error(&corr, &p.gt);
        per_frame.push(FrameError {
            timestamp_ns: p.timestamp_ns,
            et_m,
            er_deg,
            et_sym_m: sym.et / scale,
            er_sym_deg: sym.er_rad.to_degrees().min(er_deg),
        });
    }
    let et: Vec<f64> = per_frame.iter().map(|f| f.et_m).collect();
    let er: Vec<f64> = per_frame.iter().map(|f| f.er_deg).collect();
    let et_sym: Vec<f64> = per_frame.iter().map(|f| f.et_sym_m).collect();
    let er_sym: Vec<f64> = per_frame.iter().map(|f| f.er_sym_deg).collect();
    Ok(Metrics {
        frames: pairs.len(),
        scored: per_frame.len(),
        failures,
        scale,
        mean_et_m: mean(&et),
        median_et_m: median(&et),
        std_et_m: std(&et),
        mean_er_deg: mean(&er),
        median_er_deg: median(&er),
        std_er_deg: std(&er),
        symmetry: symmetry.spec.clone(),
        mean_et_sym_m: mean(&et_sym),
        median_et_sym_m: median(&et_sym),
        std_et_sym_m: std(&et_sym),
        mean_er_sym_deg: mean(&er_sym),
        median_er_sym_deg: median(&er_sym),
        std_er_sym_deg: std(&er_sym),
        reference_timestamp_ns: reference,
        per_frame,
    })
}

/// Mean (NaN for no values).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.iter().sum::<f64>() / v.len() as f64
}

/// Median, averaging the two middle values for an even count (NaN for no values).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Population standard deviation (ddof = 0; NaN for no values).
pub fn std(v: &[f64]) -> f64 {
    let m = mean(v);
    if v.is_empty() {
        return f64::NAN;
    }
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt()
}

impl Metrics {
    /// The CLI's `--json` object (NaN figures become null).
    pub fn to_json(&self) -> serde_json::Value {
        let f = |x: f64| {
            if x.is_finite() {
                serde_json::json!(x)
            } else {
                serde_json::Value::Null
            }
        };
        serde_json::json!({
            "frames": self.frames,
            "scored": self.scored,
            "failures": self.failures,
            "scale": self.scale,
            "mean_et_m": f(self.mean_et_m),
            "median_et_m": f(self.median_et_m),
            "std_et_m": f(self.std_et_m),
            "mean_er_deg": f(self.mean_er_deg),
            "median_er_deg": f(self.median_er_deg),
            "std_er_deg": f(self.std_er_deg),
            "symmetry": self.symmetry,
            "mean_et_sym_m": f(self.mean_et_sym_m),
            "median_et_sym_m": f(self.median_et_sym_m),
            "std_et_sym_m": f(self.std_et_sym_m),
            "mean_er_sym_deg": f(self.mean_er_sym_deg),
            "median_er_sym_deg": f(self.median_er_sym_deg),
            "std_er_sym_deg": f(self.std_er_sym_deg),
            "reference_timestamp_ns": self.reference_timestamp_ns,
        })
    }
}
