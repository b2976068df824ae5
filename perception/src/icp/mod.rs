//! `icp`: the built-in model-based tracker (CPU). Depth + mask + the target mesh in, pose out.
//!
//! - First frame, after `reset`, or when tracking fails: global registration over a rotation
//!   hypothesis grid ([`global`]), each refined briefly by ICP and the best scored against the
//!   image (silhouette and free space, [`score`]); the few best then refined on every target
//!   pixel to convergence and ranked by drawing each and comparing it with the frame pixel by
//!   pixel ([`compare`]). The paper's metric calibrates every frame on the first one, so its
//!   registration's error is carried into every later frame: it may take far longer than a
//!   tracked frame.
//! - Other frames: point-to-plane ICP ([`align`]) from a constant-velocity prediction of the
//!   previous pose, placed so the model's camera-facing surface sits on the scene (the range can
//!   change by a model size between captures, more than ICP's capture radius), else as predicted
//!   (placing is off when another object hides part of the target), else from the previous pose.
//!   Correspondences go from the visible scene to the nearest camera-facing model sample, so
//!   partial views (the target cut by the image border or self-occluded) only constrain what is
//!   seen; model parts hidden behind another object (the stand) are not held against a track.
//!   A fit that turned more than the target can between captures slid into a look-alike pose
//!   and is not a track; nor is such a jump carried on as the target's motion.
//! - Registration while a track exists (or after one was lost) keeps the track's branch: among
//!   the hypotheses that explain the frame as well as the best one, it takes the one nearest the
//!   prediction (after a loss: the last good pose carried on by its motion for the frames
//!   missed), so a (near-)symmetric target does not flip between its look-alike poses.
//! - A track is declared failed when too few scene points fit the model, the projected model
//!   leaves the silhouette (registration counts parts hidden behind another object as outside:
//!   with no track, a view must not be explained by hiding the part that tells look-alike poses
//!   apart), or it sits in front of observed free space; then the tracker
//!   re-registers on the same frame. A registration refused only for what another object hides
//!   is taken where it continues the track (within a capture's largest turn of its prediction):
//!   that is no look-alike. If that fails too, each track start's fit is refined against the
//!   frame's pixels and judged again; the frame is `Lost` if none passes.
//! - A track that passes those checks but whose drawing disagrees with the frame's pixels more
//!   than the frame's depth noise explains (`min_track_agreement`) may have slid onto a
//!   look-alike pose: the frame is registered again with the track as the prior, and the better
//!   explanation of the frame is taken; a track that explains the frame no better than drawing
//!   nothing is not kept (`Lost`).
//!
//! Every threshold is relative to the model's size, so the tracker is scale-equivariant (the
//! paper's depth normalisation changes nothing but rounding).

pub mod align;
pub mod cloud;
pub mod compare;
pub mod fit;
pub mod global;
pub mod model;
pub mod score;

use crate::estimator::{Estimate, EstimateKind, PoseEstimator, ScalableEstimator};
use crate::models::{Mesh, Symmetry};
use crate::pose::from_rt;
use crate::{PerceptionError, PerceptionFrame};
use align::{align, Fit, RotationPrior};
use fit::FitSteps;
use hitl_hal::pose::{self, Pose};
use model::ModelCloud;
use nalgebra::{Matrix3, Translation3, Vector3};
use score::Hidden;

/// Tuning of the tracker. Distances are fractions of the model's bounding-box diagonal `D`.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpConfig {
    /// Surface samples of the model. Their spacing bounds how finely a small view (a 2 m target
    /// at 50 m spans ~190 depth pixels at 1280x1024) pins the rotation: 4000 samples left the
    /// SITL 50 m fly-arounds at 1.6 deg, 12 000 at 0.9-1.3 deg.
    pub model_points: usize,
    /// Scene points used for tracking and final refinement.
    pub scene_points: usize,
    /// Scene points used to try each rotation hypothesis.
    pub coarse_points: usize,
    /// Viewing directions and in-plane angles of the hypothesis grid.
    pub views: usize,
    pub inplane: usize,
    /// ICP iterations per hypothesis, and for tracking / final refinement.
    pub coarse_iters: usize,
    pub track_iters: usize,
    /// Hypotheses kept after the first stage, and for full refinement.
    pub coarse_keep: usize,
    pub keep: usize,
    /// Inlier tolerance = `tol_spacing` x sample spacing + `tol_rel` x D.
    pub tol_spacing: f64,
    pub tol_rel: f64,
    /// Largest frame-to-frame motion tracked without re-registration, x D.
    pub track_max_dist_rel: f64,
    /// Acceptance: inlier fraction, silhouette fraction, free-space violation fraction.
    pub min_inlier_frac: f64,
    pub min_silhouette: f64,
    pub max_violation: f64,
    /// Fewer target points than this: no estimate.
    pub min_scene_points: usize,
    /// The inlier tolerance is at least this many standard deviations of the frame's depth
    /// noise (estimated from the frame: [`cloud::scene`]): a stereo camera's error at the
    /// target's range can exceed the model-size tolerance, and then a correct pose is not an
    /// outlier of its own data.
    pub noise_sigmas: f64,
    /// How scene depths are averaged over their neighbourhood and edge pixels left out
    /// ([`cloud::Smoothing`]). Off: on the Orbbec model's depth (independent per-pixel error) a
    /// 3x3 or 5x5 window gated at 3 sigma did not lower the fly-arounds' rotation error
    /// (docs/perception.md has the figures).
    pub smoothing: cloud::Smoothing,
    /// How far the target's turn may stray from the track's constant-motion prediction in one
    /// capture, degrees (the rotation prior of tracking, [`align::RotationPrior`]); 0: none.
    /// 1 deg, by measurement on the Orbbec model's 10 m fly-arounds: 0.3 and 0.1 deg made the
    /// prediction (its motion taken from the last two noisy estimates) lead the track astray.
    pub prior_turn_deg: f64,
    /// Registration's last stage, render and compare ([`IcpTracker::compared`]): the second
    /// stage's distinct candidates (up to `coarse_keep`) are fitted briefly to the frame's
    /// pixels; the `polish_keep` best (and the track's predictions, whatever their screening) are
    /// refined on up to `polish_points` target pixels with up to `polish_iters` ICP steps, then
    /// by `pixel_iters` pixel-wise steps, fitted to convergence and ranked by their agreement
    /// with the frame ([`compare`]). 4000 and 20 000 points gave the same figures. 0 points: the
    /// stage is off (the best `keep` candidates are refined on the tracking cloud and ranked as
    /// the earlier stages; tracked frames are not refined against the pixels either).
    pub polish_points: usize,
    pub polish_iters: usize,
    pub polish_keep: usize,
    /// Then up to this many steps pairing every target pixel with the drawn model at that pixel
    /// ([`compare::Comparer::refine`]); 0: none.
    pub pixel_iters: usize,
    /// Pixel-wise steps after each tracked frame's ICP (the same refinement), before its
    /// render-and-compare fit; 0: none. 20, as registration's: on the real path's stereo depth
    /// they bring a track back to what a well pinned frame says after the loosely pinned end-on
    /// views (docs/perception.md, "Tracked frames refined pixel by pixel"); each step draws the
    /// model once, a tenth to a fifth of what the fit's simplex draws.
    pub track_pixel_iters: usize,
    /// Render-and-compare fitting ([`fit`]), simplex iterations: of each distinct candidate
    /// registration's second stage leaves (up to `coarse_keep`), of each of the `polish_keep`
    /// best of those, and of each tracked frame after its ICP; 0: off. Only with the last stage
    /// on (`polish_points` > 0).
    pub screen_fit_iters: u64,
    pub fit_iters: u64,
    pub track_fit_iters: u64,
    /// Tracked frames whose target covers more pixels than this are not fitted: a view that
    /// large pins the pose without it (RQ3 at 5 m, 8 000-24 000 pixels: 0.07 deg mean e_r with
    /// ICP alone) and each draw costs its area (those cases play at 0.7-1.4x real time fitted).
    pub track_fit_max_pixels: usize,
    /// A fitted track that agrees with the frame less than this ([`compare`]'s agreement, 1 -
    /// disagreement per target pixel) less what the frame's depth noise costs a correct pose
    /// ([`IcpTracker::noise_cost`]) is registered again, the track its prior, and the better of
    /// the two taken; 0: never. On ideal depth a track on the target agrees 0.95-1.0, one
    /// sliding into a look-alike pose 0.30-0.72 (RQ3's 50 m sat3, docs/perception.md). A stereo
    /// camera's noise alone costs a pixel about (sigma / tol)^2 = 0.16: a track on the target
    /// agrees 0.83-0.86 there, and a threshold blind to that registered nearly every frame.
    pub min_track_agreement: f64,
}

impl Default for IcpConfig {
    fn default() -> Self {
        IcpConfig {
            model_points: 12_000,
            scene_points: 1000,
            coarse_points: 120,
            views: 60,
            inplane: 8,
            coarse_iters: 8,
            track_iters: 30,
            coarse_keep: 24,
            keep: 4,
            tol_spacing: 1.5,
            tol_rel: 0.005,
            track_max_dist_rel: 0.1,
            min_inlier_frac: 0.7,
            min_silhouette: 0.8,
            max_violation: 0.05,
            min_scene_points: 30,
            noise_sigmas: 2.5,
            smoothing: cloud::Smoothing::OFF,
            prior_turn_deg: 1.0,
            polish_points: 4000,
            polish_iters: 60,
            polish_keep: 4,
            pixel_iters: 20,
            track_pixel_iters: 20,
            screen_fit_iters: 60,
            fit_iters: 300,
            track_fit_iters: 100,
            track_fit_max_pixels: 20_000,
            min_track_agreement: 0.9,
        }
    }
}

/// A debug line on stderr; a closed stderr loses it rather than panicking the worker.
macro_rules! debug_line {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// `HITL_ICP_DEBUG` set: registration and tracking scores go to stderr (tuning on recordings
/// with `hitl eval RUN.mcap --backend icp`).
fn debug() -> bool {
    static DEBUG: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *DEBUG.get_or_init(|| std::env::var_os("HITL_ICP_DEBUG").is_some())
}

/// Scores this close to the best are ties: the frame cannot tell the hypotheses apart.
const TIE_MARGIN: f64 = 0.02;

/// Angle between two poses' rotations, radians.
fn rotation_distance(a: &Pose, b: &Pose) -> f64 {
    a.rotation.angle_to(&b.rotation)
}

/// The built-in tracker.
pub struct IcpTracker {
    cfg: IcpConfig,
    model: ModelCloud,
    grid: Vec<Matrix3<f64>>,
    /// Camera-facing surface centroid of the model under each grid rotation.
    fronts: Vec<Vector3<f64>>,
    /// The pose of the previous frame while the track holds.
    prev: Option<Pose>,
    /// The last accepted pose, the motion per frame between the last two consecutive accepted
    /// ones (none if that step was a jump no target makes between captures: a re-registration
    /// onto another branch), and the frames since: the track predicts with that motion, and after
    /// a lost track the registration prior is that motion carried on from the last good pose (a
    /// symmetric target keeps its branch through an occlusion).
    last_good: Option<Pose>,
    velocity: Option<Pose>,
    missed: u32,
    /// This frame's depth-noise tolerances (`noise_sigmas` x its estimated noise), metres: of
    /// the scene points (averaged depths) and of single pixels (the image checks).
    noise_tol: f64,
    pixel_noise_tol: f64,
    /// This frame's depth beyond which mask pixels are background ([`cloud::Scene::far_m`]).
    far_m: f64,
    /// Draws the target for registration's render and compare.
    comparer: compare::Comparer,
    /// The target's declared symmetries as body-frame transforms, identity first
    /// ([`IcpTracker::with_symmetry`]): `T` and `T * S` are the same view.
    twins: Vec<Pose>,
}

/// Frames a lost track's motion is carried on for; after that, registration has no prior.
const MAX_EXTRAPOLATED: u32 = 10;

/// Render-and-compare fitting's first simplex in registration: 2 deg and 1 % of the model's size
/// (the second stage leaves its candidates a few degrees from where they settle); in tracking,
/// 0.5 deg and 0.2 % (a tracked pose is within its noise of the best).
const FIT_TURN_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
const FIT_SHIFT: f64 = 0.01;
const TRACK_FIT_TURN_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
const TRACK_FIT_SHIFT: f64 = 0.002;

/// A turn larger than this between consecutive captures is a jump between look-alike poses, not
/// the target's motion (a fly-around turns a few degrees per capture), so it is not carried on.
const MAX_TURN_PER_FRAME_RAD: f64 = std::f64::consts::FRAC_PI_4;

/// A frame whose depth noise costs a correct pose at least this much of its agreement
/// ([`IcpTracker::depth_misses_surfaces`]) is a depth sensor's. Measured on the SITL recordings:
/// noise-free (rendered) depth costs under 1e-4 (the noise estimate is f32 rounding, under
/// 4e-7 m), the Orbbec model's stereo depth 0.1-0.2.
const SENSOR_NOISE_COST: f64 = 1e-3;

/// Outcome of one full check of a pose.
#[derive(Debug, Clone, Copy)]
struct Scored {
    fit: Fit,
    silhouette: f64,
    violation: f64,
    /// Render and compare's agreement ([`compare::Comparer::agreement`]), where it was run:
    /// then it alone ranks the pose (it judges every pixel the other terms judge on samples).
    agreement: Option<f64>,
}

impl Scored {
    fn score(&self) -> f64 {
        match self.agreement {
            Some(a) => a,
            None => self.fit.inlier_frac * self.silhouette * (1.0 - self.violation),
        }
    }
}

/// Whether a fit's drawing explains the frame no better than drawing nothing (agreement at or
/// below 0; not when it was not compared): it has left the target.
fn explains_nothing(s: &Scored) -> bool {
    s.agreement.is_some_and(|a| a <= 0.0)
}

/// `HITL_ICP_DEBUG`'s line for a candidate: its score and the four terms it is the product of.
impl std::fmt::Display for Scored {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "score {:.3} (inliers {:.3} silhouette {:.3} violation {:.3} agreement {})",
            self.score(),
            self.fit.inlier_frac,
            self.silhouette,
            self.violation,
            self.agreement.map_or("-".into(), |a| format!("{a:.3}"))
        )
    }
}

impl IcpTracker {
    /// A tracker for `mesh` given at the scale the camera sees it (lab metres).
    pub fn new(mesh: &Mesh, cfg: IcpConfig) -> Result<IcpTracker, PerceptionError> {
        let model = ModelCloud::from_mesh(mesh, cfg.model_points)?;
        let grid = global::rotation_grid(cfg.views, cfg.inplane);
        let fronts = grid.iter().map(|r| global::front_centroid(&model, r)).collect();
        let comparer = compare::Comparer::new(mesh)?;
        Ok(IcpTracker {
            cfg,
            model,
            comparer,
            grid,
            fronts,
            prev: None,
            last_good: None,
            velocity: None,
            missed: 0,
            noise_tol: 0.0,
            pixel_noise_tol: 0.0,
            far_m: f64::INFINITY,
            twins: vec![Pose::identity()],
        })
    }

    /// The target's declared symmetry (in the mesh's units: a built-in's or a sidecar's group,
    /// scaled to the lab as the mesh is). A registration with a track to keep (after a loss)
    /// then takes, of a symmetric target's twin poses that show the same view, the one nearest
    /// the track: the paper's metric is not symmetry-aware, and a track that came back on the
    /// other twin scored 180 deg for every frame after.
    pub fn with_symmetry(mut self, symmetry: &Symmetry) -> Self {
        self.twins = symmetry.elements();
        self
    }

    /// The twin of `pose` (the same view of a symmetric target) nearest `prior` in rotation.
    fn twin_nearest(&self, pose: &Pose, prior: &Pose) -> Pose {
        self.twins
            .iter()
            .map(|s| pose * s)
            .min_by(|a, b| rotation_distance(a, prior).total_cmp(&rotation_distance(b, prior)))
            .unwrap_or(*pose)
    }

    pub fn config(&self) -> &IcpConfig {
        &self.cfg
    }

    /// Whether the last frame's depth is a sensor's, which misses surfaces, rather than
    /// noise-free: its noise costs a correct pose measurably ([`SENSOR_NOISE_COST`]). Every
    /// depth camera has noise and misses surfaces (a stereo camera sees none on the stand's thin
    /// legs nor in their shadow); only rendered depth has neither, and there a pixel without
    /// depth is empty space (the orbit scene's sky). Decides what a tracked pose's drawing off
    /// the mask where the frame has no depth costs ([`compare::Comparer::disagreement`]).
    pub fn depth_misses_surfaces(&self) -> bool {
        self.noise_cost() >= SENSOR_NOISE_COST
    }

    fn tol(&self) -> f64 {
        let geometric =
            self.cfg.tol_spacing * self.model.spacing + self.cfg.tol_rel * self.model.diameter;
        geometric.max(self.noise_tol)
    }

    /// The tolerance of the image checks, which compare with single pixels' depths.
    fn pixel_tol(&self) -> f64 {
        self.tol().max(self.pixel_noise_tol)
    }

    /// What the frame's depth noise costs a correct pose's agreement ([`compare`]): each
    /// target pixel's depth difference `d` costs `min((d / tol)^2, 1)`, so noise of standard
    /// deviation `sigma` costs about `(sigma / tol)^2` (a little less: the cost is truncated at
    /// 1). 0 on ideal depth, where the geometric tolerance dwarfs the noise.
    fn noise_cost(&self) -> f64 {
        let sigma = self.pixel_noise_tol / self.cfg.noise_sigmas.max(f64::MIN_POSITIVE);
        let tol = self.pixel_tol();
        if tol > 0.0 {
            (sigma / tol).powi(2).min(1.0)
        } else {
            0.0
        }
    }

    fn full_check(
        &self,
        frame: &PerceptionFrame,
        scene: &[Vector3<f64>],
        init: &Pose,
        behind_others: Hidden,
        prior: Option<&RotationPrior>,
    ) -> Scored {
        let d = self.model.diameter;
        let fit = align(
            &self.model,
            scene,
            init,
            self.cfg.track_iters,
            self.cfg.track_max_dist_rel * d,
            self.tol(),
            true,
            prior,
        );
        let img = score::check(
            &self.model,
            frame,
            &fit.pose,
            self.pixel_tol(),
            behind_others,
            self.far_m,
        );
        Scored { fit, silhouette: img.silhouette, violation: img.violation, agreement: None }
    }

    /// The target pixels registration's last stage refines on (up to `polish_points`; none
    /// when that stage is off).
    fn pixels(&self, frame: &PerceptionFrame) -> Vec<Vector3<f64>> {
        match self.cfg.polish_points {
            0 => Vec::new(),
            n => cloud::scene(frame, n, self.model.diameter, &self.cfg.smoothing).points,
        }
    }

    fn acceptable(&self, s: &Scored) -> bool {
        s.fit.inlier_frac >= self.cfg.min_inlier_frac
            && s.silhouette >= self.cfg.min_silhouette
            && s.violation <= self.cfg.max_violation
            && pose::is_rigid(&s.fit.pose)
    }

    /// Global registration on this frame; the chosen hypothesis (acceptable or not).
    ///
    /// Three stages, each keeping the best-ranked hypotheses of the previous one: every grid
    /// rotation gets a few ICP steps on a sparse cloud; the best `coarse_keep` get more steps on a
    /// denser one; the best `keep` are refined fully. Ranking = inlier fraction x silhouette x
    /// (1 - free-space violation).
    ///
    /// `priors` (the track's predicted pose, placed on the scene and as predicted) join the final
    /// hypotheses, and the first breaks ties: see the module docs.
    fn register(
        &mut self,
        frame: &PerceptionFrame,
        scene: &[Vector3<f64>],
        pixels: &[Vector3<f64>],
        priors: &[Pose],
    ) -> Option<Scored> {
        let sparse = cloud::thin(scene, self.cfg.coarse_points / 2);
        let dense = cloud::thin(scene, self.cfg.coarse_points * 2);
        let c = cloud::centroid(&sparse);
        let d = self.model.diameter;
        let (tol, pixel_tol, far) = (self.tol(), self.pixel_tol(), self.far_m);
        let model = &self.model;
        let rank = |cloud: &[Vector3<f64>], init: &Pose, iters: usize, max_dist: f64| {
            let fit = align(model, cloud, init, iters, max_dist, 2.0 * tol, false, None);
            let img = score::check_strided(
                model,
                frame,
                &fit.pose,
                2.0 * pixel_tol,
                16,
                Hidden::Miss,
                far,
            );
            (fit.inlier_frac * img.silhouette * (1.0 - img.violation), fit.pose)
        };
        let t0 = std::time::Instant::now();
        let mut cands: Vec<(f64, Pose)> = self
            .grid
            .iter()
            .zip(&self.fronts)
            .map(|(r, front)| rank(&sparse, &from_rt(r, &(c - front)), 4, 0.3 * d))
            .collect();
        cands.sort_by(|a, b| b.0.total_cmp(&a.0));
        cands.truncate(self.cfg.coarse_keep);
        if debug() {
            debug_line!("icp stage 1 {:?}", t0.elapsed());
        }
        let mut cands: Vec<(f64, Pose)> =
            cands.iter().map(|(_, p)| rank(&dense, p, self.cfg.coarse_iters, 0.15 * d)).collect();
        cands.sort_by(|a, b| b.0.total_cmp(&a.0));
        // The last stage compares every distinct candidate with the frame pixel by pixel: the
        // ranks so far come from nearest-sample fits that a small, noisy view biases by degrees,
        // so the true pose's basin can rank below a dozen look-alikes.
        let compare = self.cfg.polish_points > 0 && !pixels.is_empty();
        let cands = if compare {
            self.distinct(cands, self.cfg.coarse_keep)
        } else {
            cands.into_iter().take(self.cfg.keep).collect()
        };
        if debug() {
            let s: Vec<String> = cands.iter().map(|c| format!("{:.3}", c.0)).collect();
            debug_line!("icp registration candidates: {} ({:?})", s.join(" "), t0.elapsed());
        }
        // The priors take the second stage's wider capture radius first, like the grid's best.
        let starts: Vec<Pose> = (cands.iter().map(|c| c.1))
            .chain(priors.iter().map(|p| rank(&dense, p, self.cfg.coarse_iters, 0.15 * d).1))
            .collect();
        let mut checked: Vec<Scored> = if compare {
            self.compared(frame, pixels, &starts, priors.len())
        } else {
            starts.iter().map(|p| self.full_check(frame, scene, p, Hidden::Miss, None)).collect()
        };
        if let Some(p) = priors.first() {
            for c in &mut checked {
                c.fit.pose = self.twin_nearest(&c.fit.pose, p);
            }
        }
        let best = checked.iter().max_by(|a, b| a.score().total_cmp(&b.score())).copied();
        let Some(p) = priors.first() else {
            return best;
        };
        if debug() {
            for c in &checked {
                let from_prior = rotation_distance(&c.fit.pose, p).to_degrees();
                debug_line!("icp checked: {c} {from_prior:.1} deg from prior");
            }
        }
        // Keep the track's branch: of the hypotheses as good as the best, the nearest to it.
        let top = best.map_or(f64::NEG_INFINITY, |b| b.score());
        checked
            .into_iter()
            .filter(|s| s.score() >= top - TIE_MARGIN && self.acceptable(s))
            .min_by(|a, b| {
                rotation_distance(&a.fit.pose, p).total_cmp(&rotation_distance(&b.fit.pose, p))
            })
            .or(best)
    }

    /// The best `n` of ranked hypotheses, no two the same pose (within a degree and 1 % of
    /// the model's size): at a far range many grid rotations converge to one pose, and the
    /// look-alike poses the last stage has to tell apart would not reach it.
    fn distinct(&self, ranked: Vec<(f64, Pose)>, n: usize) -> Vec<(f64, Pose)> {
        let mut out: Vec<(f64, Pose)> = Vec::with_capacity(n);
        for (score, pose) in ranked {
            if out.len() >= n {
                break;
            }
            if !out.iter().any(|(_, p)| self.same_pose(p, &pose)) {
                out.push((score, pose));
            }
        }
        out
    }

    /// Within a degree and 1 % of the model's size of each other.
    fn same_pose(&self, a: &Pose, b: &Pose) -> bool {
        rotation_distance(a, b) < 1f64.to_radians()
            && (a.translation.vector - b.translation.vector).norm() < 0.01 * self.model.diameter
    }

    /// Registration's last stage, render and compare ([`compare`], [`fit`]): each start fitted
    /// briefly (`screen_fit_iters`) to the frame's pixels; the `polish_keep` best of those (not
    /// two the same pose) refined by ICP on every target pixel (`polish_points`, `polish_iters`)
    /// and pixel-wise steps (`pixel_iters`), each kept only where the frame agrees better, then
    /// fitted to convergence (`fit_iters`) and ranked by their agreement with the frame. The last
    /// `priors` starts (the track's predictions) go through whatever their screening: the
    /// registration keeps the track's branch among hypotheses as good as the best, so the branch
    /// must be among them (on an end-on view the look-alikes screen as well as the track).
    fn compared(
        &mut self,
        frame: &PerceptionFrame,
        pixels: &[Vector3<f64>],
        starts: &[Pose],
        priors: usize,
    ) -> Vec<Scored> {
        self.comparer.prepare(frame, self.far_m, Hidden::Miss);
        let t0 = std::time::Instant::now();
        let (tol, far, d) = (self.pixel_tol(), self.far_m, self.model.diameter);
        let screen = FitSteps { turn_rad: FIT_TURN_RAD, shift_m: FIT_SHIFT * d, iters: 0 };
        let first_prior = starts.len().saturating_sub(priors);
        let mut screened: Vec<(f64, Pose, bool)> = starts
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let steps = FitSteps { iters: self.cfg.screen_fit_iters, ..screen };
                let (pose, cost) = fit::fit(&mut self.comparer, frame, p, steps, tol, far);
                (cost, pose, i >= first_prior)
            })
            .collect();
        screened.sort_by(|a, b| a.0.total_cmp(&b.0));
        if debug() {
            let l: Vec<String> = screened.iter().map(|(c, _, _)| format!("{c:.1}")).collect();
            debug_line!("icp screened (disagreement, px): {}", l.join(" "));
        }
        let mut picked: Vec<Pose> = Vec::new();
        let mut out = Vec::new();
        for (_, start, prior) in screened {
            if picked.len() >= self.cfg.polish_keep.max(1) && !prior {
                continue;
            }
            if picked.iter().any(|p| self.same_pose(p, &start)) {
                continue;
            }
            picked.push(start);
            let pose = self.polish(frame, pixels, &start);
            let steps = FitSteps { iters: self.cfg.fit_iters, ..screen };
            let (pose, cost) = fit::fit(&mut self.comparer, frame, &pose, steps, tol, far);
            let agreement = Some(self.comparer.agreement_of(cost));
            out.push(self.scored_at(frame, pixels, pose, Hidden::Miss, agreement));
        }
        if debug() {
            debug_line!(
                "icp compared {} starts, kept {} ({:?})",
                starts.len(),
                out.len(),
                t0.elapsed()
            );
            for (c, p) in out.iter().zip(&picked) {
                let moved = rotation_distance(&c.fit.pose, p).to_degrees();
                debug_line!("icp compared: {c}, moved {moved:.2} deg");
            }
        }
        out
    }

    /// `start` refined by ICP on every target pixel, then by pixel-wise steps, each step kept
    /// only if the frame agrees better: on a view of a few hundred noisy pixels both can slide
    /// off.
    fn polish(&mut self, frame: &PerceptionFrame, pixels: &[Vector3<f64>], start: &Pose) -> Pose {
        let (tol, far, d) = (self.pixel_tol(), self.far_m, self.model.diameter);
        let mut best = (self.comparer.disagreement(frame, start, tol, far), *start);
        let max_dist = self.cfg.track_max_dist_rel * d;
        let icp = align(
            &self.model,
            pixels,
            start,
            self.cfg.polish_iters,
            max_dist,
            self.tol(),
            true,
            None,
        );
        let cost = self.comparer.disagreement(frame, &icp.pose, tol, far);
        if cost < best.0 {
            best = (cost, icp.pose);
        }
        if self.cfg.pixel_iters > 0 {
            let pose = self.comparer.refine(frame, &best.1, self.cfg.pixel_iters, tol, far);
            let cost = self.comparer.disagreement(frame, &pose, tol, far);
            if cost < best.0 {
                best = (cost, pose);
            }
        }
        best.1
    }

    /// A tracked pose refined against the frame's pixels: from the better of the ICP fit `s` and
    /// its `start` (on a stereo camera's depth the nearest-sample pairing biases a track as it
    /// does a registration, by degrees on a small view), `track_pixel_iters` pixel-wise steps
    /// ([`compare`]), then `track_fit_iters` of render-and-compare fitting ([`fit`]) from a small
    /// simplex (a tracked pose is near), scored as a tracked fit is: drawn pixels where the frame
    /// has no depth off the mask are not held against it ([`Hidden::Skipped`]) where the frame's
    /// depth is a sensor's ([`Self::depth_misses_surfaces`]; on noise-free depth they are empty
    /// space and count as misses). Taken where it explains the frame better than the fit, turned
    /// less than a target turns between captures from the start and passes the acceptance (`s`
    /// itself may not have); else `s`. Either way with its agreement with the frame, where it was
    /// compared (not when fitting is off or the view is over `track_fit_max_pixels`).
    fn track_refined(
        &mut self,
        frame: &PerceptionFrame,
        scene: &[Vector3<f64>],
        s: &Scored,
        start: &Pose,
    ) -> Scored {
        let (steps, fits) = (self.cfg.track_pixel_iters, self.cfg.track_fit_iters);
        if (steps == 0 && fits == 0) || self.cfg.polish_points == 0 {
            return *s;
        }
        let unseen = if self.depth_misses_surfaces() { Hidden::Skipped } else { Hidden::Miss };
        self.comparer.prepare(frame, self.far_m, unseen);
        if self.comparer.target_pixels() > self.cfg.track_fit_max_pixels {
            return *s;
        }
        let (tol, far, d) = (self.pixel_tol(), self.far_m, self.model.diameter);
        let before = self.comparer.disagreement(frame, &s.fit.pose, tol, far);
        let mut best = (before, s.fit.pose);
        // The start's turn at the fit's place: the track's rotation is often the better half.
        let turned = Pose::from_parts(s.fit.pose.translation, start.rotation);
        let at_start = self.comparer.disagreement(frame, &turned, tol, far);
        if at_start < best.0 {
            best = (at_start, turned);
        }
        if steps > 0 {
            let pose = self.comparer.refine(frame, &best.1, steps, tol, far);
            let cost = self.comparer.disagreement(frame, &pose, tol, far);
            if cost < best.0 {
                best = (cost, pose);
            }
        }
        if fits > 0 {
            let near = FitSteps {
                turn_rad: TRACK_FIT_TURN_RAD,
                shift_m: TRACK_FIT_SHIFT * d,
                iters: fits,
            };
            let (pose, cost) = fit::fit(&mut self.comparer, frame, &best.1, near, tol, far);
            best = (cost, pose);
        }
        let turn = rotation_distance(&best.1, start);
        if debug() {
            debug_line!(
                "icp track refined: disagreement {before:.1} (from start {at_start:.1}) -> {:.1} of {} px, {:.2} deg from the fit",
                best.0,
                self.comparer.target_pixels(),
                rotation_distance(&best.1, &s.fit.pose).to_degrees()
            );
        }
        if best.0 < before && turn <= MAX_TURN_PER_FRAME_RAD {
            let agreement = Some(self.comparer.agreement_of(best.0));
            let refined = self.scored_at(frame, scene, best.1, Hidden::Skipped, agreement);
            if self.acceptable(&refined) {
                return refined;
            }
        }
        Scored { agreement: Some(self.comparer.agreement_of(before)), ..*s }
    }

    /// The least agreement of a track on the target: `min_track_agreement` less the frame's
    /// [`Self::noise_cost`].
    fn least_agreement(&self) -> f64 {
        self.cfg.min_track_agreement - self.noise_cost()
    }

    /// Whether a tracked fit agrees with the frame less than a track on the target does
    /// ([`Self::least_agreement`]; never when not compared).
    fn doubtful(&self, tracked: &Scored) -> bool {
        tracked.agreement.is_some_and(|a| a < self.least_agreement())
    }

    /// A tracked frame's answer: the track, unless its drawing disagrees with the frame (agreement
    /// under `min_track_agreement` less the frame's [`Self::noise_cost`]). Such a track has slid
    /// off the target (ICP and the fit stay in the basin they start in), so the frame is
    /// registered again with the track and its `start` as priors, and the registration taken if
    /// it explains the frame better. `None` (the frame is lost) where neither does and the
    /// track explains the frame no better than drawing nothing: kept, such a track led the next
    /// frames' registration onto a look-alike (two-planes' real path, 3.6 -> 44.6 deg).
    fn checked(
        &mut self,
        frame: &PerceptionFrame,
        scene: &[Vector3<f64>],
        tracked: Scored,
        start: &Pose,
        at: &Vector3<f64>,
    ) -> Option<(Scored, EstimateKind)> {
        if !self.doubtful(&tracked) {
            return Some((tracked, EstimateKind::Tracked));
        }
        let priors = [tracked.fit.pose, self.placed(start, at), *start];
        let pixels = self.pixels(frame);
        if let Some(r) = self.register(frame, scene, &pixels, &priors) {
            if debug() {
                debug_line!(
                    "icp track {} doubtful ({tracked}, under {:.3}): registered {r}",
                    frame.seq,
                    self.least_agreement()
                );
            }
            if self.acceptable(&r) && r.score() > tracked.score() {
                return Some((r, EstimateKind::Registered));
            }
        }
        // The track stands, unless it has left the target.
        if explains_nothing(&tracked) {
            return None;
        }
        Some((tracked, EstimateKind::Tracked))
    }

    /// A registration refused for the silhouette, taken after all where it continues the track:
    /// within a capture's largest turn of the track's `prior`, it is no look-alike of the
    /// target, so model parts something else (the stand) visibly hides are not held against it,
    /// as they are not against a tracked pose ([`Hidden::Skipped`]). Without a track, hiding
    /// such parts could explain a view by the part that tells look-alike poses apart.
    fn hidden_near_track(
        &self,
        frame: &PerceptionFrame,
        scene: &[Vector3<f64>],
        refused: &Scored,
        prior: Option<&Pose>,
    ) -> Option<Scored> {
        let prior = prior?;
        if rotation_distance(&refused.fit.pose, prior) > MAX_TURN_PER_FRAME_RAD {
            return None;
        }
        let pose = refused.fit.pose;
        let s = self.scored_at(frame, scene, pose, Hidden::Skipped, refused.agreement);
        if debug() {
            debug_line!("icp registration near the track, hidden parts skipped: {s}");
        }
        self.acceptable(&s).then_some(s)
    }

    /// `pose` as it stands, scored on `cloud` and the image without moving it (a pose a fit
    /// against the frame's pixels settled on).
    fn scored_at(
        &self,
        frame: &PerceptionFrame,
        cloud: &[Vector3<f64>],
        pose: Pose,
        behind_others: Hidden,
        agreement: Option<f64>,
    ) -> Scored {
        let (inlier_frac, rms) = align::quality(&self.model, cloud, &pose, self.tol(), true);
        let img =
            score::check(&self.model, frame, &pose, self.pixel_tol(), behind_others, self.far_m);
        Scored {
            fit: Fit { pose, inlier_frac, rms },
            silhouette: img.silhouette,
            violation: img.violation,
            agreement,
        }
    }

    /// `pose` moved so the model's camera-facing surface is centred on the scene point `at`.
    fn placed(&self, pose: &Pose, at: &Vector3<f64>) -> Pose {
        let r = pose.rotation.to_rotation_matrix();
        let front = global::front_centroid(&self.model, r.matrix());
        Pose::from_parts(Translation3::from(at - front), pose.rotation)
    }

    /// Where the last good pose has moved by now if the target kept its motion, placed on `at`;
    /// `None` without a good pose or after too long a loss.
    fn carried_on(&self, at: &Vector3<f64>) -> Option<Pose> {
        let mut p = self.last_good.filter(|_| self.missed <= MAX_EXTRAPOLATED)?;
        if let Some(v) = self.velocity {
            for _ in 0..=self.missed {
                p = v * p;
            }
        }
        Some(self.placed(&p, at))
    }

    fn accept(&mut self, s: &Scored, kind: EstimateKind) -> Estimate {
        let new = s.fit.pose;
        if let (Some(last), 0) = (self.last_good, self.missed) {
            let motion = new * last.inverse();
            let turn = motion.rotation.angle();
            self.velocity = (turn <= MAX_TURN_PER_FRAME_RAD).then_some(motion);
        }
        self.missed = 0;
        self.prev = Some(new);
        self.last_good = Some(new);
        Estimate { pose: Some(s.fit.pose), kind, residual_m: s.fit.rms }
    }

    fn lose(&mut self) -> Estimate {
        self.prev = None;
        self.missed = self.missed.saturating_add(1);
        Estimate::lost()
    }
}

impl PoseEstimator for IcpTracker {
    fn name(&self) -> String {
        "icp".into()
    }

    fn estimate(&mut self, frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        frame.validate()?;
        let seen =
            cloud::scene(frame, self.cfg.scene_points, self.model.diameter, &self.cfg.smoothing);
        self.noise_tol = self.cfg.noise_sigmas * seen.point_noise_m;
        self.pixel_noise_tol = self.cfg.noise_sigmas * seen.noise_m;
        let seen_point_noise = seen.point_noise_m;
        self.far_m = seen.far_m;
        let scene = seen.points;
        if scene.len() < self.cfg.min_scene_points {
            return Ok(self.lose());
        }
        let at = cloud::centroid(&scene);
        // Where the track says the target is: its motion carried one frame on. Placed on the
        // scene first (the range can change by a model size between captures), as predicted
        // (placing is off when something hides part of the target), then last frame's pose.
        let prediction = self.prev.map(|prev| self.velocity.map_or(prev, |v| v * prev));
        let starts: Vec<Pose> = match (prediction, self.prev) {
            (Some(pred), Some(prev)) => {
                vec![self.placed(&pred, &at), pred, self.placed(&prev, &at)]
            }
            _ => Vec::new(),
        };
        // The rotation prior: the prediction's turn, weighed by the points' noise against how far
        // the target's turn strays from constant motion in one capture.
        let prior = prediction.filter(|_| self.cfg.prior_turn_deg > 0.0).map(|p| RotationPrior {
            rotation: p.rotation,
            weight: (seen_point_noise / self.cfg.prior_turn_deg.to_radians()).powi(2),
        });
        let mut refused: Vec<(Scored, Pose)> = Vec::new();
        for start in &starts {
            let s = self.full_check(frame, &scene, start, Hidden::Skipped, prior.as_ref());
            // ICP is local: a fit that turned further than the target can between captures slid
            // into a look-alike pose.
            let turn = rotation_distance(&s.fit.pose, start);
            if debug() {
                debug_line!(
                    "icp track {}: inliers {:.3} silhouette {:.3} violation {:.3} turn {:.2} deg",
                    frame.seq,
                    s.fit.inlier_frac,
                    s.silhouette,
                    s.violation,
                    turn.to_degrees()
                );
            }
            if turn > MAX_TURN_PER_FRAME_RAD {
                continue;
            }
            if self.acceptable(&s) {
                // Refined against the frame's pixels where that explains them better.
                let tracked = self.track_refined(frame, &scene, &s, start);
                return Ok(match self.checked(frame, &scene, tracked, start, &at) {
                    Some((s, kind)) => self.accept(&s, kind),
                    None => self.lose(),
                });
            }
            refused.push((s, *start));
        }
        // Registration, its prior the track's prediction; without a track (reset, or lost) the
        // last good pose carried on by its motion.
        let priors = match prediction {
            Some(pred) => vec![self.placed(&pred, &at), pred],
            None => self.carried_on(&at).into_iter().collect(),
        };
        let pixels = self.pixels(frame);
        let reg = self.register(frame, &scene, &pixels, &priors);
        if debug() {
            if let Some(s) = &reg {
                debug_line!(
                    "icp register: inliers {:.3} rms {:.2e} silhouette {:.3} violation {:.3} scene {} tol {:.2e} far {:.3}",
                    s.fit.inlier_frac,
                    s.fit.rms,
                    s.silhouette,
                    s.violation,
                    scene.len(),
                    self.tol(),
                    self.far_m
                );
            }
        }
        let taken = match reg {
            Some(s) if self.acceptable(&s) => Some(s),
            Some(s) => self.hidden_near_track(frame, &scene, &s, priors.first()),
            None => None,
        };
        if let Some(s) = taken {
            return Ok(self.accept(&s, EstimateKind::Registered));
        }
        // Neither a start's fit nor a registration passed: refined against the frame's pixels,
        // a start's fit may (on the few hundred noisy pixels the stand leaves, ICP's
        // nearest-sample pairing can end a fit just outside the checks that the pixels' fit
        // passes). Not where it explains the frame no better than drawing nothing.
        for (s, start) in &refused {
            let tracked = self.track_refined(frame, &scene, s, start);
            if self.acceptable(&tracked) && !explains_nothing(&tracked) {
                return Ok(self.accept(&tracked, EstimateKind::Tracked));
            }
        }
        Ok(self.lose())
    }

    fn reset(&mut self) {
        self.prev = None;
    }
}

impl ScalableEstimator for IcpTracker {
    fn rescale_scene(&mut self, factor: f64) {
        if factor == 1.0 || !(factor.is_finite() && factor > 0.0) {
            return;
        }
        if let Ok(m) = self.model.scaled(factor) {
            self.model = m;
        }
        for f in &mut self.fronts {
            *f *= factor;
        }
        self.noise_tol *= factor;
        self.pixel_noise_tol *= factor;
        self.far_m *= factor;
        self.comparer.scale *= factor;
        let poses = [&mut self.prev, &mut self.last_good, &mut self.velocity];
        for p in poses.into_iter().flatten() {
            p.translation.vector *= factor;
        }
        for s in &mut self.twins {
            s.translation.vector *= factor;
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::TargetModel;

    fn tracker() -> IcpTracker {
        let mesh = TargetModel::from_spec("asymmetric").unwrap().lab_mesh(0.0077).unwrap();
        IcpTracker::new(&mesh, IcpConfig::default()).unwrap()
    }

    #[test]
    fn the_track_check_takes_off_what_the_noise_costs_a_correct_pose() {
        let mut t = tracker();
        // Ideal depth: nothing is taken off the check's 0.9.
        assert_eq!(t.noise_cost(), 0.0);
        // A stereo camera's noise, far above the model's sampling, sets the tolerance at 2.5
        // sigma: a correct pose loses 1 / 6.25 of its agreement to it, and the check allows it.
        t.pixel_noise_tol = t.cfg.noise_sigmas * 100.0 * t.tol();
        assert!((t.noise_cost() - 0.16).abs() < 1e-9, "{}", t.noise_cost());
        // Noise a tenth of the geometric tolerance costs (1/10)^2.
        t.pixel_noise_tol = t.cfg.noise_sigmas * 0.1 * t.tol();
        assert!((t.noise_cost() - 0.01).abs() < 1e-9, "{}", t.noise_cost());
    }

    #[test]
    fn the_tracks_prediction_reaches_the_last_comparison_however_it_screens() {
        // One start at the truth and the track's prediction 120 deg off it; the last stage keeps
        // one start. The truth screens better, and the prediction is compared all the same (the
        // registration's tie-break needs it there); a start that is not a prediction is not.
        let mesh = TargetModel::from_spec("asymmetric").unwrap().lab_mesh(0.1).unwrap();
        let cfg = IcpConfig { polish_keep: 1, ..IcpConfig::default() };
        let mut t = IcpTracker::new(&mesh, cfg).unwrap();
        let k = crate::testing::intrinsics_hfov(160, 128, 36.5);
        let truth = crate::testing::look_pose(1.0, 0.5, -0.3, 0.2);
        let frame = crate::testing::render(&mesh, &truth, &k, 1);
        let off = truth
            * nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 120f64.to_radians());
        let pixels = t.pixels(&frame);
        let compared = t.compared(&frame, &pixels, &[truth, off], 1);
        assert_eq!(compared.len(), 2);
        assert!(rotation_distance(&compared[0].fit.pose, &truth) < 1f64.to_radians());
        assert!(rotation_distance(&compared[1].fit.pose, &truth) > 10f64.to_radians());
        assert!(compared[0].score() > compared[1].score());
        assert_eq!(t.compared(&frame, &pixels, &[truth, off], 0).len(), 1);
    }
}
