//! `mono`: the monocular baseline (`--perception mono`), an estimator that sees the light. Colour
//! image and the run's mask in, pose out; never the depth image. In the spirit of the paper's
//! planned DreamSat-Pose (learned 2D-3D matching), done classically:
//!
//! - The target is what the mask holds and the light shows ([`features::lit_pixels`]): a pixel
//!   darker than `dark_level` is shadow, as black as space to a camera.
//! - First frame, or a lost track: the pose whose drawn silhouette best overlaps the lit pixels
//!   ([`register`]). Its corners (FAST-9) get BRIEF descriptors (imageproc) and are lifted onto
//!   the model at that pose (the drawn surface under each corner, [`crate::silhouette`]): the
//!   keyframe, 2D descriptors with 3D model points.
//! - Other frames: the frame's corners are matched to the keyframe's descriptors, and the pose
//!   comes from PnP with RANSAC on the matches ([`ransac`]), from the previous pose. When the
//!   view has turned away from the keyframe (too few matches agree, or the pose turned more than
//!   `keyframe_turn_deg`), the frame becomes the keyframe at its estimated pose.
//! - Too few lit pixels, too few agreeing matches and a failed registration: `Lost`.
//!
//! Lighting changes the answer: a dark frame has no corners and a thin lit silhouette, and a
//! backlit target shows a crescent whose registration is poor. The shadow line moves over the
//! target with the Sun, and corners on it are not on the model: RANSAC drops what it can. The
//! keyframe's model points carry its pose's error (the baseline drifts at each new keyframe).

pub mod features;
pub mod ransac;
pub mod register;

use crate::estimator::{Estimate, EstimateKind, PoseEstimator};
use crate::models::Mesh;
use crate::silhouette::{SilhouetteRenderer, TARGET};
use crate::{PerceptionError, PerceptionFrame};
use features::{Features, Window};
use hitl_hal::{Intrinsics, Pose};
use imageproc::binary_descriptors::brief::{BriefDescriptor, TestPair};
use nalgebra::{Point3, Vector3};
use register::Registration;

/// Tuning of the monocular baseline.
#[derive(Debug, Clone, PartialEq)]
pub struct MonoConfig {
    /// Luma (0-255) at or below which a pixel is shadow.
    pub dark_level: u8,
    /// Fewer lit target pixels than this: no estimate.
    pub min_lit_px: usize,
    /// FAST-9 threshold (grey levels).
    pub fast_threshold: u8,
    /// Strongest corners kept per frame.
    pub max_features: usize,
    /// A match is within this many of the 256 descriptor bits, and nearer than `ratio` times
    /// the second nearest.
    pub max_hamming: u32,
    pub ratio: f64,
    /// RANSAC hypotheses, and the reprojection tolerance of an inlier, pixels.
    pub ransac_iterations: usize,
    pub inlier_px: f64,
    /// A track needs this many agreeing matches.
    pub min_inliers: usize,
    /// A new keyframe when fewer than this fraction of the keyframe's points agree, or the pose
    /// turned more than `keyframe_turn_deg` from the keyframe's.
    pub keyframe_keep_frac: f64,
    pub keyframe_turn_deg: f64,
    /// A registration is accepted at this intersection over union of silhouettes.
    pub min_iou: f64,
    /// Registration: viewing directions and in-plane angles, and the faces the silhouettes are
    /// drawn with.
    pub register_views: usize,
    pub register_inplane: usize,
    pub register_faces: usize,
}

impl Default for MonoConfig {
    fn default() -> Self {
        MonoConfig {
            dark_level: 8,
            min_lit_px: 40,
            fast_threshold: 12,
            max_features: 400,
            max_hamming: 64,
            ratio: 0.85,
            ransac_iterations: 100,
            inlier_px: 3.0,
            min_inliers: 10,
            keyframe_keep_frac: 0.5,
            keyframe_turn_deg: 10.0,
            min_iou: 0.6,
            register_views: 60,
            register_inplane: 12,
            register_faces: 2000,
        }
    }
}

/// Descriptors of one frame with the model points under their corners, and the pose they were
/// lifted at.
struct Keyframe {
    descriptors: Vec<BriefDescriptor>,
    body: Vec<Vector3<f64>>,
    pose: Pose,
}

/// The monocular baseline.
pub struct MonoTracker {
    cfg: MonoConfig,
    registration: Registration,
    /// Draws the full model to lift corners onto it.
    lifter: SilhouetteRenderer,
    pairs: Vec<TestPair>,
    prev: Option<Pose>,
    keyframe: Option<Keyframe>,
    lit: Vec<u8>,
    drawn: Vec<u8>,
    frames: u64,
}

impl MonoTracker {
    /// A baseline for `mesh` given at the scale the camera sees it (lab metres).
    pub fn new(mesh: &Mesh, cfg: MonoConfig) -> Result<MonoTracker, PerceptionError> {
        Ok(MonoTracker {
            registration: Registration::new(mesh, &cfg)?,
            lifter: SilhouetteRenderer::new(mesh)?,
            cfg,
            pairs: features::test_pairs(),
            prev: None,
            keyframe: None,
            lit: Vec::new(),
            drawn: Vec::new(),
            frames: 0,
        })
    }

    /// The keyframe of `feats` at `pose`: each corner the model covers there, with the model
    /// point under it.
    fn lift(&mut self, feats: &Features, pose: &Pose, k: &Intrinsics) -> Keyframe {
        self.lifter.draw(pose, k, 0, &mut self.drawn);
        let inv = pose.inverse();
        let mut key = Keyframe { descriptors: Vec::new(), body: Vec::new(), pose: *pose };
        for (d, &(u, v)) in feats.descriptors.iter().zip(&feats.pixels) {
            let Some(z) = self.surface_under(u as usize, v as usize, k) else { continue };
            let cam = Point3::new((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z);
            key.body.push((inv * cam).coords);
            key.descriptors.push(d.clone());
        }
        key
    }

    /// The depth of the model point under a corner at pixel (u, v): the nearest drawn surface
    /// in its 3 x 3 neighbourhood, when most of it is target. A corner on the silhouette or on
    /// a step in depth is the front surface's (the edge that makes it), which the pixel centre
    /// may miss by a pixel.
    fn surface_under(&self, u: usize, v: usize, k: &Intrinsics) -> Option<f64> {
        let (w, h) = (k.width as usize, k.height as usize);
        if u == 0 || v == 0 || u + 1 >= w || v + 1 >= h {
            return None;
        }
        let (mut near, mut n) = (f32::INFINITY, 0);
        for vv in v - 1..=v + 1 {
            for uu in u - 1..=u + 1 {
                let idx = vv * w + uu;
                if self.drawn.get(idx) == Some(&TARGET) {
                    if let Some(z) = self.lifter.surface_depth(idx) {
                        near = near.min(z);
                        n += 1;
                    }
                }
            }
        }
        let centre = v * w + u;
        let on = self.drawn.get(centre) == Some(&TARGET);
        let z = if on { self.lifter.surface_depth(centre) } else { None };
        (n >= 4).then_some(f64::from(z.unwrap_or(near)))
    }

    /// Frame-to-keyframe tracking: the consensus pose, or `None` when too few matches agree.
    fn track(&mut self, feats: &Features, k: &Intrinsics, prev: &Pose) -> Option<Estimate> {
        let key = self.keyframe.as_ref()?;
        let matches = features::match_descriptors(&feats.descriptors, &key.descriptors, &self.cfg);
        let body: Vec<Vector3<f64>> = matches.iter().map(|&(_, j)| key.body[j]).collect();
        let pixels: Vec<(f64, f64)> = matches.iter().map(|&(i, _)| feats.pixels[i]).collect();
        let fit = ransac::pnp_ransac(
            &body,
            &pixels,
            k,
            prev,
            self.cfg.ransac_iterations,
            self.cfg.inlier_px,
            0x9e37_79b9 ^ self.frames,
        )?;
        if fit.inliers < self.cfg.min_inliers {
            return None;
        }
        if std::env::var_os("HITL_MONO_DEBUG").is_some() {
            eprintln!(
                "mono: {} corners, keyframe {}, {} matches, {} agree, {:.2} px",
                feats.pixels.len(),
                key.body.len(),
                matches.len(),
                fit.inliers,
                fit.rms_px
            );
        }
        let turned = fit.pose.rotation.angle_to(&key.pose.rotation).to_degrees();
        let thin = (fit.inliers as f64) < self.cfg.keyframe_keep_frac * key.body.len() as f64;
        if thin || turned > self.cfg.keyframe_turn_deg {
            self.keyframe = Some(self.lift(feats, &fit.pose, k));
        }
        // The residual in metres at the target's range.
        let residual_m = fit.rms_px * fit.pose.translation.vector.z / k.fx;
        Some(Estimate { pose: Some(fit.pose), kind: EstimateKind::Tracked, residual_m })
    }

    fn lose(&mut self) -> Estimate {
        self.prev = None;
        self.keyframe = None;
        Estimate::lost()
    }
}

impl PoseEstimator for MonoTracker {
    fn name(&self) -> String {
        "mono".into()
    }

    fn estimate(&mut self, frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        frame.validate()?;
        if frame.color.is_empty() {
            return Err(PerceptionError::BadInput(
                "the monocular baseline needs the colour image; this frame has none".into(),
            ));
        }
        self.frames += 1;
        let k = frame.intrinsics;
        let mut lit = std::mem::take(&mut self.lit);
        let (n_lit, window) = features::lit_pixels(frame, &self.cfg, &mut lit);
        let out = match window {
            Some(window) if n_lit >= self.cfg.min_lit_px => {
                let feats = features::detect(frame, &lit, window, &self.cfg, &self.pairs);
                self.estimate_lit(&feats, &lit, window, &k)
            }
            _ => self.lose(),
        };
        self.lit = lit;
        Ok(out)
    }

    fn reset(&mut self) {
        self.prev = None;
        self.keyframe = None;
    }
}

impl MonoTracker {
    fn estimate_lit(
        &mut self,
        feats: &Features,
        lit: &[u8],
        window: Window,
        k: &Intrinsics,
    ) -> Estimate {
        if let Some(prev) = self.prev {
            if let Some(e) = self.track(feats, k, &prev) {
                self.prev = e.pose;
                return e;
            }
        }
        let prior = self.prev;
        match self.registration.register(lit, k, window, prior.as_ref()) {
            Some((pose, iou)) if iou >= self.cfg.min_iou => {
                self.keyframe = Some(self.lift(feats, &pose, k));
                self.prev = Some(pose);
                Estimate { pose: Some(pose), kind: EstimateKind::Registered, residual_m: 0.0 }
            }
            _ => self.lose(),
        }
    }
}

#[cfg(test)]
mod tests;
