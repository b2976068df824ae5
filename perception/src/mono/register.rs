//! Registration from the lit silhouette alone (first frame, a lost track): every rotation of a
//! grid ([`crate::icp::global::rotation_grid`]) is drawn ([`crate::silhouette`]) in a small
//! camera cropped about the lit pixels, placed so its silhouette has the lit area and centroid,
//! and scored by intersection over union; the best few are refined by a local search of the six
//! pose parameters in a finer camera. A silhouette cannot tell a view from its mirror twin nor
//! the shadowed part from space: that is what a monocular estimator in the dark has to go on.

use super::features::Window;
use super::MonoConfig;
use crate::models::{decimate::decimate, Mesh};
use crate::silhouette::{SilhouetteRenderer, TARGET};
use crate::PerceptionError;
use hitl_hal::{Intrinsics, Pose};
use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Longest side of the coarse and the fine crop, pixels.
const COARSE_PX: f64 = 48.0;
const FINE_PX: f64 = 128.0;

/// Hypotheses refined in the fine crop.
const KEEP: usize = 4;

/// A silhouette registration for one target.
pub struct Registration {
    renderer: SilhouetteRenderer,
    grid: Vec<Matrix3<f64>>,
    diameter: f64,
    drawn: Vec<u8>,
}

/// The lit pixels resampled into a small camera: its intrinsics and mask.
struct Crop {
    k: Intrinsics,
    mask: Vec<u8>,
    area: f64,
    centroid: (f64, f64),
}

impl Crop {
    /// A camera of about `size` pixels on its longer side seeing `window` of `k`'s image (grown
    /// by a quarter each side), and `lit` sampled at its pixel centres.
    fn new(lit: &[u8], k: &Intrinsics, window: Window, size: f64) -> Option<Crop> {
        let (w, h) = (f64::from(window.u1 - window.u0 + 1), f64::from(window.v1 - window.v0 + 1));
        let (gu, gv) = (0.25 * w + 2.0, 0.25 * h + 2.0);
        let (u0, v0) = (f64::from(window.u0) - gu, f64::from(window.v0) - gv);
        let s = (size / (w + 2.0 * gu).max(h + 2.0 * gv)).min(1.0);
        let (cw, ch) = (((w + 2.0 * gu) * s).ceil() as u32, ((h + 2.0 * gv) * s).ceil() as u32);
        let ck = Intrinsics {
            width: cw,
            height: ch,
            fx: k.fx * s,
            fy: k.fy * s,
            cx: (k.cx - u0 + 0.5) * s - 0.5,
            distortion: k.distortion,
            cy: (k.cy - v0 + 0.5) * s - 0.5,
        };
        let mut mask = vec![0u8; (cw * ch) as usize];
        let (mut area, mut su, mut sv) = (0.0, 0.0, 0.0);
        for y in 0..ch {
            for x in 0..cw {
                let u = (u0 + (f64::from(x) + 0.5) / s - 0.5).round();
                let v = (v0 + (f64::from(y) + 0.5) / s - 0.5).round();
                if u < 0.0 || v < 0.0 || u >= f64::from(k.width) || v >= f64::from(k.height) {
                    continue;
                }
                if lit[v as usize * k.width as usize + u as usize] != 0 {
                    mask[(y * cw + x) as usize] = TARGET;
                    area += 1.0;
                    su += f64::from(x);
                    sv += f64::from(y);
                }
            }
        }
        (area >= 4.0).then(|| Crop { k: ck, mask, area, centroid: (su / area, sv / area) })
    }
}

impl Registration {
    /// For `mesh` (lab metres): drawn decimated to `cfg.register_faces` faces.
    pub fn new(mesh: &Mesh, cfg: &MonoConfig) -> Result<Registration, PerceptionError> {
        let coarse = decimate(mesh, cfg.register_faces.max(100))?.mesh;
        Ok(Registration {
            renderer: SilhouetteRenderer::new(&coarse)?,
            grid: crate::icp::global::rotation_grid(cfg.register_views, cfg.register_inplane),
            diameter: mesh.diameter(),
            drawn: Vec::new(),
        })
    }

    /// Intersection over union of the target drawn at `pose` with the crop's mask, and the
    /// drawn area and centroid.
    fn score(&mut self, pose: &Pose, crop: &Crop) -> (f64, f64, (f64, f64)) {
        self.renderer.draw(pose, &crop.k, 0, &mut self.drawn);
        let w = crop.k.width as usize;
        let (mut both, mut either, mut area, mut su, mut sv) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (i, (&d, &m)) in self.drawn.iter().zip(&crop.mask).enumerate() {
            if d != 0 {
                area += 1.0;
                su += (i % w) as f64;
                sv += (i / w) as f64;
            }
            if d != 0 && m != 0 {
                both += 1.0;
            }
            if d != 0 || m != 0 {
                either += 1.0;
            }
        }
        let iou = if either > 0.0 { both / either } else { 0.0 };
        let c = if area > 0.0 { (su / area, sv / area) } else { (0.0, 0.0) };
        (iou, area, c)
    }

    /// Rotation `r` placed so its silhouette has the crop's area and centroid; its IoU.
    fn place(&mut self, r: &Matrix3<f64>, crop: &Crop) -> Option<(Pose, f64)> {
        let k = &crop.k;
        let size = f64::from(k.width.max(k.height));
        let z_ref = k.fx * self.diameter / (0.6 * size);
        let ray = |c: (f64, f64)| Vector3::new((c.0 - k.cx) / k.fx, (c.1 - k.cy) / k.fy, 1.0);
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
        let at = |t: Vector3<f64>| Pose::from_parts(Translation3::from(t), rot);
        let (_, area, c) = self.score(&at(ray(crop.centroid) * z_ref), crop);
        if area < 1.0 {
            return None;
        }
        let z = z_ref * (area / crop.area).sqrt();
        let mut t = ray(crop.centroid) * z;
        // The silhouette's centroid is off the origin's image by (c - centroid) at z_ref; at z
        // that offset shrinks by z_ref / z, so the shift that cancels it is the same in metres.
        t.x -= (c.0 - crop.centroid.0) * z_ref / k.fx;
        t.y -= (c.1 - crop.centroid.1) * z_ref / k.fy;
        let pose = at(t);
        let (iou, _, _) = self.score(&pose, crop);
        Some((pose, iou))
    }

    /// Local search of the six pose parameters from `pose` for a higher IoU: steps of
    /// rotation about the camera axes and translation, halved when none helps.
    fn refine(&mut self, pose: Pose, crop: &Crop) -> (Pose, f64) {
        let mut best = pose;
        let (mut iou, _, _) = self.score(&best, crop);
        let (mut rot_step, mut t_step) = (8f64.to_radians(), 0.05 * self.diameter);
        while rot_step > 0.4f64.to_radians() {
            let mut improved = false;
            for axis in 0..6 {
                for sign in [1.0, -1.0] {
                    let mut d = Vector3::zeros();
                    d[axis % 3] = sign;
                    let cand = if axis < 3 {
                        let c = best.translation.vector;
                        let turn = UnitQuaternion::from_scaled_axis(d * rot_step);
                        Pose::from_parts(Translation3::from(c), turn * best.rotation)
                    } else {
                        let z = best.translation.vector.z.max(1e-6);
                        // Along the view axis a step changes the size as much as a side step moves.
                        let scale = if axis == 5 { z / self.diameter } else { 1.0 };
                        Pose::from_parts(
                            Translation3::from(best.translation.vector + d * t_step * scale),
                            best.rotation,
                        )
                    };
                    let (s, _, _) = self.score(&cand, crop);
                    if s > iou {
                        best = cand;
                        iou = s;
                        improved = true;
                    }
                }
            }
            if !improved {
                rot_step *= 0.5;
                t_step *= 0.5;
            }
        }
        (best, iou)
    }

    /// The pose whose silhouette best explains the `lit` pixels in `window` of an image of
    /// intrinsics `k`, with its IoU (in the fine crop). `prior` (the last tracked pose) is tried
    /// as a hypothesis too. `None` when the lit pixels are too few to crop.
    pub fn register(
        &mut self,
        lit: &[u8],
        k: &Intrinsics,
        window: Window,
        prior: Option<&Pose>,
    ) -> Option<(Pose, f64)> {
        let coarse = Crop::new(lit, k, window, COARSE_PX)?;
        let fine = Crop::new(lit, k, window, FINE_PX)?;
        let mut scored: Vec<(Pose, f64)> = Vec::with_capacity(self.grid.len() + 1);
        for i in 0..self.grid.len() {
            let r = self.grid[i];
            if let Some(h) = self.place(&r, &coarse) {
                scored.push(h);
            }
        }
        scored.sort_by(|a, b| b.1.total_cmp(&a.1));
        scored.truncate(KEEP);
        if let Some(p) = prior {
            let r = p.rotation.to_rotation_matrix().into_inner();
            if let Some(h) = self.place(&r, &coarse) {
                scored.push(h);
            }
        }
        // The crops share the image's rays, so a pose placed in one is placed in the other.
        scored
            .into_iter()
            .map(|(pose, _)| self.refine(pose, &fine))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }
}
