//! Render and compare: how well a pose hypothesis explains the frame pixel by pixel. The target
//! mesh is drawn at the pose at the frame's full resolution ([`SilhouetteRenderer`]) and each
//! pixel of the drawing or of the frame's target is judged on its mask and its depth.
//!
//! The same drawing refines a pose ([`Comparer::refine`]): each target pixel's observed point
//! is held against the drawn surface at that very pixel (projective association, as
//! KinectFusion pairs a depth map with its model's rendering), not against the nearest model
//! sample. A stereo camera's error lies along the pixel's ray; a nearest-sample pairing turns it
//! into a pull toward whichever surface is nearest (at a crease, the other face), which on the
//! Orbbec model's depth biased a registration by degrees; pairing by pixel does not.
//!
//! Registration fits and ranks its final candidates by the drawing's disagreement with the
//! frame ([`Comparer::disagreement`], [`super::fit`]); tracking refines each tracked pose by it:
//! the cheaper tests used earlier (model samples inside the mask, scene points near the model)
//! score a pose that leaves part of the target unexplained as well as one that explains all of
//! it, and at a far range, where the target spans a few hundred pixels, a look-alike pose
//! (turned about an axis that is no symmetry of the target) passes them.

use super::align::Steps;
use super::score::Hidden;
use crate::models::mesh::triangle_cross;
use crate::models::Mesh;
use crate::silhouette::{SilhouetteRenderer, TARGET};
use crate::{PerceptionError, PerceptionFrame};
use hitl_hal::Pose;
use nalgebra::{Translation3, Vector3};

/// Levenberg-Marquardt damping of the pixel-wise steps ([`Steps::damp`]). Undamped, a view that
/// pins a turn only weakly (the SITL fly-around's first view of the asymmetric target) swung by
/// 0.2 deg from step to step as pixels at the outline came and went.
const LM_DAMPING: f64 = 0.5;

/// Draws the target for the comparison; its mesh is at the scale the tracker was built for, and
/// `scale` follows the tracker's later rescaling ([`crate::ScalableEstimator`]).
pub struct Comparer {
    renderer: SilhouetteRenderer,
    drawn: Vec<u8>,
    /// Each target face's unit normal, body frame (for [`Self::refine`]).
    normals: Vec<Vector3<f64>>,
    /// Scratch of [`Self::refine`]: drawn point, its surface normal, observed point.
    pairs: Vec<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
    residuals: Vec<f64>,
    /// The frame's target pixels' box ([`Self::prepare`]).
    target_box: Option<[usize; 4]>,
    /// How many target pixels the frame has ([`Self::prepare`]): the agreement's unit.
    target_pixels: usize,
    /// What a drawn pixel off the mask where the frame has no depth costs ([`Self::prepare`]).
    unseen_off_mask: Hidden,
    /// The tracker's model scale over the drawn mesh's.
    pub scale: f64,
}

impl Comparer {
    /// A comparer of `mesh` (as the tracker's model is built from it); refuses a mesh that
    /// cannot be drawn.
    pub fn new(mesh: &Mesh) -> Result<Comparer, PerceptionError> {
        let renderer = SilhouetteRenderer::new(mesh)?.with_faces();
        let normals = (0..mesh.faces().len())
            .map(|i| {
                let c = triangle_cross(&mesh.triangle(i));
                Vector3::new(c[0], c[1], c[2]).try_normalize(0.0).unwrap_or_else(Vector3::zeros)
            })
            .collect();
        Ok(Comparer {
            renderer,
            drawn: Vec::new(),
            normals,
            pairs: Vec::new(),
            residuals: Vec::new(),
            target_box: None,
            target_pixels: 0,
            unseen_off_mask: Hidden::Miss,
            scale: 1.0,
        })
    }

    /// Draws the target at `pose` (the mesh at the tracker's scale).
    fn draw(&mut self, frame: &PerceptionFrame, pose: &Pose) -> Option<[usize; 4]> {
        // The drawn mesh is the tracker's model over `scale`: the same image at the translation
        // over `scale`, its depths times `scale`.
        let at = Translation3::from(pose.translation.vector / self.scale) * pose.rotation;
        self.renderer.draw(&at, &frame.intrinsics, 0, &mut self.drawn).window
    }

    /// The box of the frame's target pixels (in the mask, with depth no farther than `far_m`),
    /// pixels (u0, v0, u1, v1 inclusive), and their count; set before comparing on a frame.
    /// `unseen_off_mask`: what a drawn pixel off the mask where the frame has no depth costs
    /// ([`Self::disagreement`]).
    pub fn prepare(&mut self, frame: &PerceptionFrame, far_m: f64, unseen_off_mask: Hidden) {
        let w = frame.intrinsics.width as usize;
        let mut bx: Option<[usize; 4]> = None;
        self.target_pixels = 0;
        for i in (0..frame.depth_m.len()).filter(|&i| frame.is_target(i)) {
            if f64::from(frame.depth_m[i]) > far_m {
                continue;
            }
            self.target_pixels += 1;
            let (u, v) = (i % w, i / w);
            bx = Some(match bx {
                None => [u, v, u, v],
                Some([u0, v0, u1, v1]) => [u0.min(u), v0.min(v), u1.max(u), v1.max(v)],
            });
        }
        self.target_box = bx;
        self.unseen_off_mask = unseen_off_mask;
    }

    /// The drawn surface's depth at pixel `i`, metres (infinite off the drawing).
    fn drawn_depth(&self, i: usize) -> f64 {
        match self.drawn.get(i) {
            Some(&TARGET) => {
                self.renderer.surface_depth(i).map_or(f64::INFINITY, |z| f64::from(z) * self.scale)
            }
            _ => f64::INFINITY,
        }
    }

    /// Refines `init` with up to `iters` point-to-plane steps pairing each target pixel's
    /// observed point with the drawn surface at the same pixel and that face's normal. Observed
    /// depths beyond `far_m` are left out; the pairs are trimmed at 3x their median residual,
    /// not below `tol`.
    pub fn refine(
        &mut self,
        frame: &PerceptionFrame,
        init: &Pose,
        iters: usize,
        tol: f64,
        far_m: f64,
    ) -> Pose {
        let k = frame.intrinsics;
        let w = k.width as usize;
        let point = |u: usize, v: usize, z: f64| {
            let (x, y) = k.unproject(u as f64, v as f64);
            Vector3::new(x * z, y * z, z)
        };
        let mut t = *init;
        for _ in 0..iters {
            let window = self.draw(frame, &t);
            let mut pairs = std::mem::take(&mut self.pairs);
            pairs.clear();
            let r = t.rotation.to_rotation_matrix();
            for i in pixels(window, w).filter(|&i| self.drawn[i] == TARGET) {
                let observed = f64::from(frame.depth_m[i]);
                if !frame.is_target(i) || observed > far_m {
                    continue;
                }
                let Some(n) = self.renderer.face_at(i).and_then(|f| self.normals.get(f)) else {
                    continue;
                };
                let (u, v) = (i % w, i / w);
                pairs.push((point(u, v, self.drawn_depth(i)), r * n, point(u, v, observed)));
            }
            let step = self.step(&pairs, &t, tol);
            self.pairs = pairs;
            let Some((next, done)) = step else {
                break;
            };
            t = next;
            if done {
                break;
            }
        }
        t
    }

    /// One Gauss-Newton step over the pairs: the moved pose and whether it has converged.
    fn step(
        &mut self,
        pairs: &[(Vector3<f64>, Vector3<f64>, Vector3<f64>)],
        t: &Pose,
        tol: f64,
    ) -> Option<(Pose, bool)> {
        if pairs.len() < 6 {
            return None;
        }
        self.residuals.clear();
        self.residuals.extend(pairs.iter().map(|(m, n, s)| n.dot(&(m - s)).abs()));
        let mid = self.residuals.len() / 2;
        let (_, med, _) = self.residuals.select_nth_unstable_by(mid, f64::total_cmp);
        let bound = (3.0 * *med).max(tol);
        let c = pairs.iter().map(|p| p.2).sum::<Vector3<f64>>() / pairs.len() as f64;
        let mut eq = Steps::new(c);
        for (m, n, s) in pairs {
            eq.add(m, n, s, bound, 1.0);
        }
        eq.damp(LM_DAMPING);
        let x = eq.solve(None, t)?;
        let done = x.fixed_rows::<3>(0).norm() < 1e-7 && x.fixed_rows::<3>(3).norm() < 1e-7 * c.z;
        Some((eq.apply(t, &x), done))
    }

    /// How much of the frame the pose at `pose` leaves unexplained, in target pixels.
    ///
    /// Judged: every pixel the drawn target covers, and every target pixel of the frame (in the
    /// mask, with depth no farther than `far_m`: farther is what a mask with a margin shows behind
    /// the outline). A pixel only one of them calls target costs 1. Where both do, the depths'
    /// difference `d` costs `min((d / tol)^2, 1)`: a truncated quadratic, so within the noise the
    /// cost still says which pose lies closer to the observed surface, and a pixel off by more
    /// (drawn in front of the observed surface: free space; behind it: the frame sees something
    /// nearer) costs what a silhouette miss does. Costing nothing: a target pixel without depth
    /// (a stereo camera has none at edges and in shadows), and a drawn pixel outside the mask
    /// where the frame sees something nearer than the drawing (the stand in front of the
    /// target: what it hides is no evidence against the pose). A drawn pixel outside the mask
    /// where the frame has no depth costs 1 when [`Self::prepare`] was told [`Hidden::Miss`]
    /// (registration: the outline is most of what a small view says), nothing with
    /// [`Hidden::Skipped`] (tracking: a stereo camera sees no depth on the stand's thin legs
    /// nor in the shadow they cast, and a track already says where the target is). The tracker
    /// says [`Hidden::Skipped`] only on a depth sensor's frames
    /// ([`super::IcpTracker::depth_misses_surfaces`]): on rendered depth a pixel without depth is
    /// empty space (the orbit scene's sky), and a track's outline there counts.
    pub fn disagreement(
        &mut self,
        frame: &PerceptionFrame,
        pose: &Pose,
        tol: f64,
        far_m: f64,
    ) -> f64 {
        let window = self.draw(frame, pose);
        let w = frame.intrinsics.width as usize;
        // Off both boxes neither says target: only their union is looked at.
        let union = match (window, self.target_box) {
            (Some(a), Some(b)) => {
                Some([a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])])
            }
            (a, b) => a.or(b),
        };
        let mut cost = 0.0;
        for i in pixels(union, w) {
            let observed = f64::from(frame.depth_m[i]);
            let has_depth = observed.is_finite() && observed > 0.0;
            let in_mask = frame.in_silhouette(i);
            if self.drawn[i] != TARGET {
                if in_mask && has_depth && observed <= far_m {
                    cost += 1.0;
                }
            } else if !in_mask {
                let hidden = if has_depth {
                    observed < self.drawn_depth(i) - tol
                } else {
                    self.unseen_off_mask == Hidden::Skipped
                };
                if !hidden {
                    cost += 1.0;
                }
            } else if has_depth {
                let u = (observed - self.drawn_depth(i)) / tol;
                cost += (u * u).min(1.0);
            }
        }
        cost
    }

    /// How well the pose at `pose` explains the frame: 1 minus its [`Self::disagreement`] per
    /// target pixel of the frame (1: every pixel agrees to well within the noise; 0 or less: no
    /// better than drawing nothing). 0 on a frame without target pixels.
    pub fn agreement(&mut self, frame: &PerceptionFrame, pose: &Pose, tol: f64, far_m: f64) -> f64 {
        let cost = self.disagreement(frame, pose, tol, far_m);
        self.agreement_of(cost)
    }

    /// The frame's target pixels (in the mask, with depth no farther than `far_m`), as the last
    /// [`Self::prepare`] counted them.
    pub fn target_pixels(&self) -> usize {
        self.target_pixels
    }

    /// The agreement of a pose whose [`Self::disagreement`] is `cost`.
    pub fn agreement_of(&self, cost: f64) -> f64 {
        if self.target_pixels == 0 {
            return 0.0;
        }
        1.0 - cost / self.target_pixels as f64
    }
}

/// The pixel indices of a box (u0, v0, u1, v1 inclusive) in an image `w` wide; none without one.
fn pixels(window: Option<[usize; 4]>, w: usize) -> impl Iterator<Item = usize> {
    let [u0, v0, u1, v1] = window.unwrap_or([1, 1, 0, 0]);
    (v0..=v1).flat_map(move |v| (u0..=u1).map(move |u| v * w + u))
}
