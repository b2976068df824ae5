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
//!   re-registers on the same frame and reports `Lost` if that fails too.
//!
//! Every threshold is relative to the model's size, so the tracker is scale-equivariant (the
//! paper's depth normalisation changes nothing but rounding).

pub mod align;
pub mod cloud;
pub mod compare;
pub mod global;
pub mod model;
pub mod score;

use crate::estimator::{Estimate, EstimateKind, PoseEstimator, ScalableEstimator};
use crate::models::Mesh;
use crate::pose::from_rt;
use crate::{PerceptionError, PerceptionFrame};
use align::{align, Fit, RotationPrior};
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
    /// Registration's last stage: its distinct candidates scoring within `polish_margin` of the
    /// best (at most `polish_keep`: look-alikes of one another) are refined on up to
    /// `polish_points` target pixels with up to `polish_iters` ICP steps, then on every target
    /// pixel by `pixel_iters` pixel-wise steps, and ranked by render and compare ([`compare`]).
    /// 4000 and 20 000 points gave the same figures (the pixel-wise steps take every pixel).
    /// 0 points: the stage is off (the final candidates are refined on the tracking cloud and
    /// ranked as the earlier stages; the tracker before it, with `track_pixel_iters` 0).
    pub polish_points: usize,
    pub polish_iters: usize,
    pub polish_keep: usize,
    pub polish_margin: f64,
    /// Then up to this many steps pairing every target pixel with the drawn model at that pixel
    /// ([`compare::Comparer::refine`]); 0: none.
    pub pixel_iters: usize,
    /// Pixel-wise steps after each tracked frame's ICP (the same refinement); 0: none, the
    /// default: 5 took the SITL fly-around from 1.67 to 1.29 deg but each step draws the model,
    /// and on the 55 000-face sat3 a tracked frame took 3.3x as long (docs/perception.md).
    pub track_pixel_iters: usize,
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
            polish_margin: 0.1,
            pixel_iters: 20,
            track_pixel_iters: 0,
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
}

/// Frames a lost track's motion is carried on for; after that, registration has no prior.
const MAX_EXTRAPOLATED: u32 = 10;

/// A turn larger than this between consecutive captures is a jump between look-alike poses, not
/// the target's motion (a fly-around turns a few degrees per capture), so it is not carried on.
const MAX_TURN_PER_FRAME_RAD: f64 = std::f64::consts::FRAC_PI_4;

/// Outcome of one full check of a pose.
#[derive(Debug, Clone, Copy)]
struct Scored {
    fit: Fit,
    silhouette: f64,
    violation: f64,
    /// Render and compare's pixel agreement ([`compare`]); 1 where it was not run.
    agreement: f64,
}

impl Scored {
    fn score(&self) -> f64 {
        self.fit.inlier_frac * self.silhouette * (1.0 - self.violation) * self.agreement
    }
}

/// `HITL_ICP_DEBUG`'s line for a candidate: its score and the four terms it is the product of.
impl std::fmt::Display for Scored {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "score {:.3} (inliers {:.3} silhouette {:.3} violation {:.3} agreement {:.3})",
            self.score(),
            self.fit.inlier_frac,
            self.silhouette,
            self.violation,
            self.agreement
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
        })
    }

    pub fn config(&self) -> &IcpConfig {
        &self.cfg
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
        Scored { fit, silhouette: img.silhouette, violation: img.violation, agreement: 1.0 }
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
        let (tol, pixel_tol) = (self.tol(), self.pixel_tol());
        let rank = |cloud: &[Vector3<f64>], init: &Pose, iters: usize, max_dist: f64| {
            let fit = align(&self.model, cloud, init, iters, max_dist, 2.0 * tol, false, None);
            let img = score::check_strided(
                &self.model,
                frame,
                &fit.pose,
                2.0 * pixel_tol,
                16,
                Hidden::Miss,
                self.far_m,
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
        let cands = if self.cfg.polish_points > 0 {
            self.distinct(cands)
        } else {
            cands.into_iter().take(self.cfg.keep).collect()
        };
        if debug() {
            let s: Vec<String> = cands.iter().map(|c| format!("{:.3}", c.0)).collect();
            debug_line!("icp registration candidates: {} ({:?})", s.join(" "), t0.elapsed());
        }
        let mut checked: Vec<Scored> = cands
            .iter()
            .map(|(_, p)| self.full_check(frame, scene, p, Hidden::Miss, None))
            .collect();
        // The priors take the second stage's wider capture radius first, like the grid's best.
        for p in priors {
            let (_, near) = rank(&dense, p, self.cfg.coarse_iters, 0.15 * d);
            checked.push(self.full_check(frame, scene, &near, Hidden::Miss, None));
        }
        let checked = self.polished(frame, pixels, checked);
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

    /// The best `keep` of ranked hypotheses, no two the same pose (within a degree and 1 % of
    /// the model's size): at a far range many grid rotations converge to one pose, and the
    /// look-alike poses the last stage has to tell apart would not reach it. (With the last
    /// stage off, `polish_points` 0, the best `keep` as they come.)
    fn distinct(&self, ranked: Vec<(f64, Pose)>) -> Vec<(f64, Pose)> {
        let mut out: Vec<(f64, Pose)> = Vec::with_capacity(self.cfg.keep);
        for (score, pose) in ranked {
            if out.len() >= self.cfg.keep {
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

    /// Registration's last stage: the candidates within `polish_margin` of the best (at most
    /// `polish_keep`, and not two within a degree of each other) refined on the dense cloud and
    /// ranked with render and compare; the others are dropped. Off (`polish_points` 0): as given.
    fn polished(
        &mut self,
        frame: &PerceptionFrame,
        dense: &[Vector3<f64>],
        mut checked: Vec<Scored>,
    ) -> Vec<Scored> {
        if self.cfg.polish_points == 0 || dense.is_empty() {
            return checked;
        }
        self.comparer.prepare(frame, self.far_m);
        let t0 = std::time::Instant::now();
        checked.sort_by(|a, b| b.score().total_cmp(&a.score()));
        let top = checked.first().map_or(f64::NEG_INFINITY, Scored::score);
        let mut picked: Vec<Pose> = Vec::new();
        let mut out = Vec::new();
        for c in checked.iter().filter(|c| c.score() >= top - self.cfg.polish_margin) {
            if picked.len() >= self.cfg.polish_keep.max(1) {
                break;
            }
            if picked.iter().any(|p| self.same_pose(p, &c.fit.pose)) {
                continue;
            }
            picked.push(c.fit.pose);
            let fit = align(
                &self.model,
                dense,
                &c.fit.pose,
                self.cfg.polish_iters,
                self.cfg.track_max_dist_rel * self.model.diameter,
                self.tol(),
                true,
                None,
            );
            let (tol, far) = (self.pixel_tol(), self.far_m);
            let mut fit = fit;
            let mut agreement = self.comparer.agreement(frame, &fit.pose, tol, far);
            if self.cfg.pixel_iters > 0 {
                // On a view of a few hundred pixels the pixel-wise steps can slide off: kept only
                // if the frame agrees at least as well.
                let pose = self.comparer.refine(frame, &fit.pose, self.cfg.pixel_iters, tol, far);
                let refined = self.comparer.agreement(frame, &pose, tol, far);
                if refined >= agreement {
                    let (inlier_frac, rms) =
                        align::quality(&self.model, dense, &pose, self.tol(), true);
                    fit = Fit { pose, inlier_frac, rms };
                    agreement = refined;
                }
            }
            let img = score::check(&self.model, frame, &fit.pose, tol, Hidden::Miss, far);
            out.push(Scored {
                fit,
                silhouette: img.silhouette,
                violation: img.violation,
                agreement,
            });
        }
        if debug() {
            debug_line!(
                "icp polished {} candidates on {} points ({:?})",
                out.len(),
                dense.len(),
                t0.elapsed()
            );
            for (c, p) in out.iter().zip(&picked) {
                let moved = rotation_distance(&c.fit.pose, p).to_degrees();
                debug_line!("icp polished: {c}, moved {moved:.2} deg");
            }
        }
        out
    }

    /// A tracked pose refined pixel by pixel (`track_pixel_iters` steps, [`compare`]): on a
    /// stereo camera's depth the nearest-sample pairing biases it as it does a registration.
    /// The refined pose is taken only if it explains the frame's pixels at least as well
    /// ([`compare::Comparer::agreement`]) and turned less than a target turns between captures.
    fn track_refined(&mut self, frame: &PerceptionFrame, s: Scored) -> Scored {
        if self.cfg.track_pixel_iters == 0 {
            return s;
        }
        self.comparer.prepare(frame, self.far_m);
        let (tol, far) = (self.pixel_tol(), self.far_m);
        let pose = self.comparer.refine(frame, &s.fit.pose, self.cfg.track_pixel_iters, tol, far);
        let before = self.comparer.agreement(frame, &s.fit.pose, tol, far);
        let after = self.comparer.agreement(frame, &pose, tol, far);
        let turn = rotation_distance(&pose, &s.fit.pose);
        if debug() {
            debug_line!(
                "icp track refined: agreement {before:.3} -> {after:.3}, turned {:.2} deg",
                turn.to_degrees()
            );
        }
        if after < before || turn > MAX_TURN_PER_FRAME_RAD {
            return s;
        }
        Scored { fit: Fit { pose, ..s.fit }, ..s }
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
            if self.acceptable(&s) && turn <= MAX_TURN_PER_FRAME_RAD {
                let s = self.track_refined(frame, s);
                return Ok(self.accept(&s, EstimateKind::Tracked));
            }
        }
        // Registration, its prior the track's prediction; without a track (reset, or lost) the
        // last good pose carried on by its motion.
        let priors = match prediction {
            Some(pred) => vec![self.placed(&pred, &at), pred],
            None => self.carried_on(&at).into_iter().collect(),
        };
        // Registration's last stage refines on every target pixel (up to `polish_points`).
        let pixels = match self.cfg.polish_points {
            0 => Vec::new(),
            n => cloud::scene(frame, n, self.model.diameter, &self.cfg.smoothing).points,
        };
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
        match reg {
            Some(s) if self.acceptable(&s) => Ok(self.accept(&s, EstimateKind::Registered)),
            _ => Ok(self.lose()),
        }
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
    }
}
