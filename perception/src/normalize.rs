//! The paper's depth normalisation for estimators with range assumptions.
//!
//! Given the median target depth `d` over the mask, `k = d / 1 m`; the estimator sees
//! `depth' = depth / k` and a mesh scaled by `s' = s / k` (a uniform scaling of the whole scene
//! about the camera centre, so every pixel's footprint is unchanged), and its translation is
//! scaled back, `t = k * t'`. Rotation is unaffected. The intrinsics do not change.

use crate::estimator::{Estimate, PoseEstimator, ScalableEstimator};
use crate::{PerceptionError, PerceptionFrame};

/// Median depth (metres) over the target pixels (mask and valid depth), `None` if there are none.
pub fn median_target_depth(frame: &PerceptionFrame) -> Option<f64> {
    let mut d: Vec<f32> = (0..frame.depth_m.len())
        .filter(|&i| frame.is_target(i))
        .map(|i| frame.depth_m[i])
        .collect();
    if d.is_empty() {
        return None;
    }
    let n = d.len();
    d.sort_by(|a, b| a.total_cmp(b));
    Some(if n % 2 == 1 { d[n / 2] as f64 } else { 0.5 * (d[n / 2 - 1] as f64 + d[n / 2] as f64) })
}

/// Returns the frame with depth divided by `k` and the factor `k` (median target depth / 1 m).
pub fn normalize_frame(frame: &PerceptionFrame) -> Result<(PerceptionFrame, f64), PerceptionError> {
    frame.validate()?;
    let k = median_target_depth(frame)
        .filter(|k| k.is_finite() && *k > 0.0)
        .ok_or_else(|| PerceptionError::BadFrame("no target pixel with valid depth".into()))?;
    let mut out = frame.clone();
    // New depth; colour and mask stay shared with `frame`.
    out.depth_m =
        std::sync::Arc::new(frame.depth_m.iter().map(|d| (*d as f64 / k) as f32).collect());
    Ok((out, k))
}

/// Scales an estimate made on a normalised frame back to the original scene (`t = k * t'`).
pub fn unscale_estimate(mut e: Estimate, k: f64) -> Estimate {
    if let Some(p) = e.pose.as_mut() {
        p.translation.vector *= k;
    }
    e.residual_m *= k;
    e
}

/// Wraps an estimator so it always sees the target at a median depth of 1 m.
pub struct DepthNormalized<E> {
    inner: E,
    /// Factor the inner estimator's scene is currently scaled by (1/k of the last frame).
    current: f64,
}

impl<E: ScalableEstimator> DepthNormalized<E> {
    pub fn new(inner: E) -> Self {
        DepthNormalized { inner, current: 1.0 }
    }

    pub fn inner(&self) -> &E {
        &self.inner
    }
}

impl<E: ScalableEstimator> PoseEstimator for DepthNormalized<E> {
    fn name(&self) -> String {
        format!("{}+depth-normalised", self.inner.name())
    }

    fn estimate(&mut self, frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        let (normalized, k) = normalize_frame(frame)?;
        let factor = 1.0 / k;
        // Tell the inner estimator its scene (mesh, remembered pose) is now `factor` of the
        // original: relative to what it had, that is factor / current.
        self.inner.rescale_scene(factor / self.current);
        self.current = factor;
        let e = self.inner.estimate(&normalized)?;
        Ok(unscale_estimate(e, k))
    }

    fn reset(&mut self) {
        self.inner.reset();
    }
}
