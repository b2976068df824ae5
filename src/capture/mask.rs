//! The target mask every capture gets (`hitl run --mask sim|rendered|none`, docs/perception.md).
//!
//! - `sim`: the simulated camera's own mask (its renderer's ground truth), as delivered;
//! - `rendered`: the controller draws the target's silhouette from its own lab configuration
//!   (camera mount, target pose, the tripod as an occluder, the target model) seen from the
//!   camera pose of the arm's reported joints at the exposure (the pose `/pose/gt` records), with
//!   the frame's own intrinsics, and grows it by a margin of pixels: the counterpart of the
//!   simulator's mask for a real camera, which has none;
//! - `none`: the estimator gets no mask (and none is recorded).
//!
//! Drawing happens on the capture intake's thread, never on the loop's. When the simulated camera
//! also delivered its own mask, a `rendered` run compares the two (the simulator's is then used
//! for nothing else): how much of the true silhouette the drawn mask covers, their area ratio,
//! and the IoU of the silhouette before the margin.

use hitl_hal::{Intrinsics, Pose};
use hitl_perception::silhouette::{capsule_mesh, SilhouetteRenderer};
use hitl_perception::Mesh;
use hitl_trajectories::lab::{LabConfig, SceneKind};
use std::fmt;
use std::str::FromStr;
use std::time::Instant;

/// Where a capture's target mask comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskSource {
    /// The simulated camera's own mask (`--camera sim` only).
    Sim,
    /// Drawn by the controller from its lab and the arm's reported joints at the exposure.
    Rendered,
    /// No mask.
    None,
}

/// The default `--mask-margin-px` (docs/perception.md: how it was chosen).
pub const DEFAULT_MARGIN_PX: u32 = 2;

impl FromStr for MaskSource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "sim" => Ok(Self::Sim),
            "rendered" => Ok(Self::Rendered),
            "none" => Ok(Self::None),
            other => Err(format!("{other:?} is not a mask source: expected sim, rendered or none")),
        }
    }
}

impl fmt::Display for MaskSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Sim => "sim",
            Self::Rendered => "rendered",
            Self::None => "none",
        })
    }
}

/// What the masks of a run were, for the run's summary.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct MaskStats {
    pub source: Option<MaskSource>,
    pub margin_px: u32,
    /// Masks drawn (`rendered`), and those with no target pixel (target out of view).
    pub drawn: u64,
    pub empty: u64,
    /// Drawing time, milliseconds: mean and largest.
    pub draw_ms_mean: f64,
    pub draw_ms_max: f64,
    /// Frames where the simulator's own mask was there to compare with (SITL).
    pub compared: u64,
    /// Fraction of the simulator's silhouette the drawn mask covers: mean and smallest.
    pub coverage_mean: f64,
    pub coverage_min: f64,
    /// Drawn mask area over the simulator's silhouette area: mean and largest.
    pub area_ratio_mean: f64,
    pub area_ratio_max: f64,
    /// IoU of the drawn silhouette before the margin with the simulator's: mean and smallest.
    pub iou_mean: f64,
    pub iou_min: f64,
}

impl MaskStats {
    /// One line for the run's summary.
    pub fn describe(&self) -> String {
        let Some(source) = self.source else { return "mask: none".into() };
        let mut s = match source {
            MaskSource::Rendered => format!(
                "mask: rendered, margin {} px; {} drawn, {} empty (target out of view), draw time \
                 mean {:.2} ms max {:.2} ms",
                self.margin_px, self.drawn, self.empty, self.draw_ms_mean, self.draw_ms_max
            ),
            other => format!("mask: {other}"),
        };
        if self.compared > 0 {
            s.push_str(&format!(
                "\nrendered mask against the simulator's over {} frames: covers mean {:.2} % \
                 (min {:.2} %), area x{:.3} (max x{:.3}); silhouette IoU mean {:.4} (min {:.4})",
                self.compared,
                100.0 * self.coverage_mean,
                100.0 * self.coverage_min,
                self.area_ratio_mean,
                self.area_ratio_max,
                self.iou_mean,
                self.iou_min
            ));
        }
        s
    }
}

/// Draws the masks of a `rendered` run and keeps their statistics.
pub struct MaskDrawer {
    renderer: SilhouetteRenderer,
    margin_px: u32,
    silhouette_only: Vec<u8>,
    stats: MaskStats,
    draw_ms_sum: f64,
    coverage_sum: f64,
    ratio_sum: f64,
    iou_sum: f64,
}

impl MaskDrawer {
    /// A drawer of `target` (lab metres, body frame) in `lab`: the tripod under it is an occluder
    /// where there is one to see (always with a real camera; in the simulator's `lab` scene).
    /// Refuses a target that cannot be drawn.
    pub fn new(
        target: &Mesh,
        lab: &LabConfig,
        tripod_visible: bool,
        margin_px: u32,
    ) -> Result<Self, String> {
        let mut renderer = SilhouetteRenderer::new(target)
            .map_err(|e| format!("--mask rendered: the target model cannot be drawn: {e}"))?;
        if tripod_visible {
            let target_from_base = lab.target_in_base().inverse();
            if let Some((_, c)) = lab.keepouts_base().into_iter().find(|(n, _)| *n == "tripod") {
                if c.radius > 0.0 && (c.b - c.a).norm() > 1e-9 {
                    let (v, f) = capsule_mesh(
                        target_from_base * c.a,
                        target_from_base * c.b,
                        c.radius,
                        24,
                        6,
                    );
                    renderer = renderer.with_occluder(&v, &f);
                }
            }
        }
        Ok(Self {
            renderer,
            margin_px,
            silhouette_only: Vec::new(),
            stats: MaskStats {
                source: Some(MaskSource::Rendered),
                margin_px,
                coverage_min: f64::NAN,
                area_ratio_max: f64::NAN,
                iou_min: f64::NAN,
                ..MaskStats::default()
            },
            draw_ms_sum: 0.0,
            coverage_sum: 0.0,
            ratio_sum: 0.0,
            iou_sum: 0.0,
        })
    }

    /// Whether the tripod is seen by the camera a run uses: a real camera always sees it; the
    /// simulated one only in its `lab` scene (the `orbit` scene does not draw it).
    pub fn tripod_visible(simulated_camera: bool, lab: &LabConfig) -> bool {
        !simulated_camera || lab.scene.kind == SceneKind::Lab
    }

    /// The mask of a capture with the target at `camera_t_target` (mono8: 255 target, 0 else).
    /// `truth` is the simulator's own mask when there is one, to compare with.
    pub fn draw(
        &mut self,
        camera_t_target: &Pose,
        k: &Intrinsics,
        truth: Option<&[u8]>,
    ) -> Vec<u8> {
        let t0 = Instant::now();
        let mut mask = Vec::new();
        let drawn = self.renderer.draw(camera_t_target, k, self.margin_px, &mut mask);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let s = &mut self.stats;
        s.drawn += 1;
        if drawn.mask_px == 0 {
            s.empty += 1;
        }
        self.draw_ms_sum += ms;
        s.draw_ms_max = s.draw_ms_max.max(ms);
        s.draw_ms_mean = self.draw_ms_sum / s.drawn as f64;
        if let Some(truth) = truth.filter(|t| t.len() == mask.len()) {
            self.compare(camera_t_target, k, &mask, truth);
        }
        mask
    }

    fn compare(&mut self, pose: &Pose, k: &Intrinsics, mask: &[u8], truth: &[u8]) {
        let true_px = truth.iter().filter(|&&t| t != 0).count();
        if true_px == 0 {
            return;
        }
        // The silhouette before the margin, for the IoU (drawn again: a margin-0 drawing).
        let mut plain = std::mem::take(&mut self.silhouette_only);
        if self.margin_px == 0 {
            plain.clear();
            plain.extend_from_slice(mask);
        } else {
            self.renderer.draw(pose, k, 0, &mut plain);
        }
        let covered = mask.iter().zip(truth).filter(|(m, t)| **m != 0 && **t != 0).count();
        let mask_px = mask.iter().filter(|&&m| m != 0).count();
        let inter = plain.iter().zip(truth).filter(|(m, t)| **m != 0 && **t != 0).count();
        let union = plain.iter().zip(truth).filter(|(m, t)| **m != 0 || **t != 0).count();
        self.silhouette_only = plain;
        let coverage = covered as f64 / true_px as f64;
        let ratio = mask_px as f64 / true_px as f64;
        let iou = inter as f64 / union.max(1) as f64;
        let s = &mut self.stats;
        s.compared += 1;
        let n = s.compared as f64;
        self.coverage_sum += coverage;
        self.ratio_sum += ratio;
        self.iou_sum += iou;
        s.coverage_mean = self.coverage_sum / n;
        s.area_ratio_mean = self.ratio_sum / n;
        s.iou_mean = self.iou_sum / n;
        s.coverage_min =
            if s.coverage_min.is_nan() { coverage } else { s.coverage_min.min(coverage) };
        s.area_ratio_max =
            if s.area_ratio_max.is_nan() { ratio } else { s.area_ratio_max.max(ratio) };
        s.iou_min = if s.iou_min.is_nan() { iou } else { s.iou_min.min(iou) };
    }

    pub fn stats(&self) -> &MaskStats {
        &self.stats
    }
}
