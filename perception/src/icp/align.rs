//! Point-to-plane ICP: scene points (camera frame) against the model's surface samples, trimmed
//! correspondences, Gauss-Newton steps in a frame centred on the scene centroid ([`Steps`], which
//! registration's pixel-wise refinement shares, [`super::compare`]).

use super::cloud::centroid;
use super::model::ModelCloud;
use hitl_hal::Pose;
use nalgebra::{Matrix6, Translation3, UnitQuaternion, Vector3, Vector6};

/// How an alignment ended.
#[derive(Debug, Clone, Copy)]
pub struct Fit {
    pub pose: Pose,
    /// Fraction of scene points within the inlier tolerance of the model.
    pub inlier_frac: f64,
    /// RMS point-to-plane distance of the inliers, metres.
    pub rms: f64,
}

/// A prior on the rotation (the track's prediction), as a Tikhonov term of the Gauss-Newton
/// steps: `weight` x |rotation vector from the estimate to `rotation`|^2 joins the squared
/// point-to-plane residuals. `weight` = (the points' noise / the prediction's turn error)^2,
/// metres^2 per rad^2: where the scene pins the rotation (most views) it changes nothing
/// measurable; where it does not (a flat panel seen face on pins no turn about its normal; a
/// small far view of noisy depth), the rotation follows the target's motion instead of the
/// noise.
#[derive(Debug, Clone, Copy)]
pub struct RotationPrior {
    pub rotation: UnitQuaternion<f64>,
    pub weight: f64,
}

/// The normal equations of one Gauss-Newton point-to-plane step about a centre `c` (the scene
/// centroid): unknowns the rotation vector and the translation, each pair weighed by Tukey's
/// biweight of its residual over the trimming bound (a point half-way to the bound counts half
/// as much, so stray points (the stand, what lies behind the outline in a mask with a margin, a
/// stereo camera's outliers) pull less than the noise-sized ones).
pub struct Steps {
    a: Matrix6<f64>,
    b: Vector6<f64>,
    c: Vector3<f64>,
    used: usize,
}

impl Steps {
    pub fn new(c: Vector3<f64>) -> Steps {
        Steps { a: Matrix6::zeros(), b: Vector6::zeros(), c, used: 0 }
    }

    /// Adds a model point `m` with normal `n` (camera frame) against the scene point `s`,
    /// weighed `weight` times the biweight; a residual at or past `bound` adds nothing.
    pub fn add(
        &mut self,
        m: &Vector3<f64>,
        n: &Vector3<f64>,
        s: &Vector3<f64>,
        bound: f64,
        weight: f64,
    ) {
        let arm = m - self.c;
        let r0 = n.dot(&(m - s));
        let u = r0 / bound;
        if u.abs() >= 1.0 {
            return;
        }
        let j = Vector6::new(
            arm.y * n.z - arm.z * n.y,
            arm.z * n.x - arm.x * n.z,
            arm.x * n.y - arm.y * n.x,
            n.x,
            n.y,
            n.z,
        );
        let wt = (1.0 - u * u).powi(2) * weight;
        self.a += j * j.transpose() * wt;
        self.b += j * r0 * wt;
        self.used += 1;
    }

    /// Levenberg-Marquardt damping: each unknown's own curvature raised by the factor
    /// `1 + lambda`, so a direction the pairs pin only weakly takes a shorter step.
    pub fn damp(&mut self, lambda: f64) {
        for k in 0..6 {
            self.a[(k, k)] *= 1.0 + lambda;
        }
    }

    /// The step (rotation vector, then translation) from the pose `t`; `None` with fewer than six
    /// pairs or a singular system.
    pub fn solve(&mut self, prior: Option<&RotationPrior>, t: &Pose) -> Option<Vector6<f64>> {
        if self.used < 6 {
            return None;
        }
        let damping = 1e-9 * self.a.trace().max(1e-30);
        for k in 0..6 {
            self.a[(k, k)] += damping;
        }
        if let Some(p) = prior.filter(|p| p.weight > 0.0 && p.weight.is_finite()) {
            // The step's rotation part is pulled toward the turn that reaches the prior.
            let to_prior = (p.rotation * t.rotation.inverse()).scaled_axis();
            for k in 0..3 {
                self.a[(k, k)] += p.weight;
                self.b[k] -= p.weight * to_prior[k];
            }
        }
        self.a.cholesky().map(|ch| ch.solve(&(-self.b)))
    }

    /// `t` moved by the step `x` about the centre.
    pub fn apply(&self, t: &Pose, x: &Vector6<f64>) -> Pose {
        let w = Vector3::new(x[0], x[1], x[2]);
        let v = Vector3::new(x[3], x[4], x[5]);
        let step = Pose::new(v, w);
        let mut out = Translation3::from(self.c) * step * Translation3::from(-self.c) * t;
        // Re-normalise against accumulated rounding.
        out.rotation = UnitQuaternion::new_normalize(out.rotation.into_inner());
        out
    }
}

/// Refines `init` with up to `iters` point-to-plane steps. `max_dist` bounds correspondences at
/// the start; later the bound follows 3x the median distance (not below `tol`).
#[allow(clippy::too_many_arguments)]
pub fn align(
    model: &ModelCloud,
    scene: &[Vector3<f64>],
    init: &Pose,
    iters: usize,
    max_dist: f64,
    tol: f64,
    facing: bool,
    prior: Option<&RotationPrior>,
) -> Fit {
    let mut t = *init;
    let c = centroid(scene);
    let mut bound = max_dist;
    let mut pairs: Vec<(Vector3<f64>, usize, f64)> = Vec::with_capacity(scene.len());
    let mut dists: Vec<f64> = Vec::with_capacity(scene.len());
    for _ in 0..iters {
        let r = t.rotation.to_rotation_matrix();
        let tr = t.translation.vector;
        let rt = r.transpose();
        let view_body = |s: &Vector3<f64>| -(rt * s).normalize();
        pairs.clear();
        dists.clear();
        for s in scene {
            let sb = rt * (s - tr);
            let (i, d2) = if facing {
                model.nearest_facing(&sb, &view_body(s), 4)
            } else {
                model.nearest(&sb)
            };
            let d = d2.sqrt();
            dists.push(d);
            pairs.push((*s, i, d));
        }
        let mut sorted = dists.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let med = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        bound = bound.min((3.0 * med).max(tol));
        let mut eq = Steps::new(c);
        for (s, i, d) in &pairs {
            if *d > bound {
                continue;
            }
            let m = r * model.points[*i] + tr;
            let n = r * model.normals[*i];
            eq.add(&m, &n, s, bound, 1.0);
        }
        let Some(x) = eq.solve(prior, &t) else {
            break;
        };
        // The step about the scene centroid: rotation vector, then translation.
        t = eq.apply(&t, &x);
        if x.fixed_rows::<3>(0).norm() < 1e-9 && x.fixed_rows::<3>(3).norm() < 1e-9 * model.diameter
        {
            break;
        }
    }
    let (inlier_frac, rms) = quality(model, scene, &t, tol, facing);
    Fit { pose: t, inlier_frac, rms }
}

/// Inlier fraction (nearest-sample distance <= `tol`) and RMS point-to-plane distance of inliers.
pub fn quality(
    model: &ModelCloud,
    scene: &[Vector3<f64>],
    t: &Pose,
    tol: f64,
    facing: bool,
) -> (f64, f64) {
    if scene.is_empty() {
        return (0.0, f64::NAN);
    }
    let r = t.rotation.to_rotation_matrix();
    let tr = t.translation.vector;
    let rt = r.transpose();
    let mut inliers = 0usize;
    let mut sq = 0.0;
    for s in scene {
        let sb = rt * (s - tr);
        let (i, d2) = if facing {
            model.nearest_facing(&sb, &(-(rt * s).normalize()), 4)
        } else {
            model.nearest(&sb)
        };
        if d2.sqrt() <= tol {
            inliers += 1;
            let e = model.normals[i].dot(&(sb - model.points[i]));
            sq += e * e;
        }
    }
    let rms = if inliers > 0 { (sq / inliers as f64).sqrt() } else { f64::NAN };
    (inliers as f64 / scene.len() as f64, rms)
}
