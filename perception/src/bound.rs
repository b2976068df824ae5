//! How tightly one frame can pin the target's pose at all, whatever estimates it.
//!
//! [`depth_bound`] is the Cramer-Rao bound of the frame's depth: each target pixel's depth is the
//! target's surface at the true pose plus Gaussian noise of a known standard deviation (a stereo
//! camera's grows with z^2), so the Fisher information of the pose's six parameters (a turn
//! about the target's origin and a shift, camera axes) is the sum over the pixels of
//! `g g^T / sigma^2`, `g` the drawn depth's derivative at that pixel. Its inverse is the least
//! covariance an unbiased estimator of the pose from those pixels can have; the rotation block's
//! principal axes are the turns the frame pins best and least. Counted are the frame's target
//! pixels that measure the target's surface (in the mask, with depth within 5 sigma of the
//! drawing at the truth): what a stereo camera leaves without depth (edges, shadows) says
//! nothing, and a pixel whose drawn depth jumps under a small step (an inner outline) is left
//! out rather than let a step stand for a slope.
//!
//! The mask is no statistical evidence but a limit: [`mask_room`] counts what a pose turned from
//! the truth would be charged for (drawn pixels off the mask where the frame has no depth, target
//! pixels the drawing leaves uncovered), so how far a turn can go before the mask says anything.
//!
//! The paper's metric calibrates every frame on the first (docs/perception.md, "Metrics"): a
//! frame scores the difference of its error and the first frame's. [`calibrated_floor`] is the
//! least that difference can be expected to be for an estimator unbiased on each frame whose
//! frames' errors are independent; averaged over a run, a floor under its mean rotation error
//! (the `first_view_bound` example prints both for a recording). A tracker, whose errors on
//! consecutive frames are alike, is not bound by it: it scores less where it carries the first
//! frame's error along.

use crate::models::Mesh;
use crate::silhouette::{SilhouetteRenderer, TARGET};
use crate::{PerceptionError, PerceptionFrame};
use hitl_hal::Pose;
use nalgebra::{Matrix3, Matrix6, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6};

/// Derivative steps: a turn of 0.05 deg and a shift of 20 um; both move a target the size of
/// the lab's (2-5 cm) far less than a depth pixel's noise, and far more than f32 depth resolves.
const TURN_STEP_RAD: f64 = 8.7e-4;
const SHIFT_STEP_M: f64 = 2e-5;

/// A turn the frame pins: its axis (unit, camera frame) and the 1-sigma bound of an unbiased
/// estimate's turn about it, radians (infinite where the frame says nothing of it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Turn {
    pub axis: Vector3<f64>,
    pub sigma_rad: f64,
}

/// What one frame's depth can say of the pose ([`depth_bound`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PoseBound {
    /// Target pixels with depth (in the mask).
    pub target_pixels: usize,
    /// Of those, the pixels that measure the target's surface and were counted (the others are
    /// [`PoseBound::measuring`]).
    pub counted: usize,
    /// The counted pixels' mean squared residual at the truth over sigma^2: about 1 where the
    /// noise model describes the frame.
    pub chi2_per_pixel: f64,
    /// The rotation block's principal turns, best pinned first.
    pub turns: [Turn; 3],
    /// The measured surface's centroid, camera frame (metres): the pivot [`mask_room`] turns
    /// about.
    pub centroid: Vector3<f64>,
    /// The pixels measuring the target's surface (indices, row-major).
    measuring_pixels: Vec<usize>,
}

impl PoseBound {
    /// The pixels that measure the target's surface (in the mask, depth within 5 sigma of the
    /// drawing at the truth), counted or not.
    pub fn measuring(&self) -> usize {
        self.measuring_pixels.len()
    }

    /// The root-mean-square turn of an unbiased estimate about the two best pinned axes,
    /// radians: the floor under its rotation error even where the third turn is left to the mask.
    pub fn pinned_rms_rad(&self) -> f64 {
        self.turns[0].sigma_rad.hypot(self.turns[1].sigma_rad)
    }

    /// The expected size of an unbiased estimate's turn about the two best pinned axes, radians:
    /// the floor under the mean rotation error of a run calibrated on this frame, the third turn
    /// taken as exact.
    pub fn pinned_mean_rad(&self) -> f64 {
        expected_turn(&self.pinned_covariance())
    }

    /// The covariance of an unbiased estimate's turn about the two best pinned axes (camera axes,
    /// rad^2; the third turn taken as exact, so a direction only the mask bounds costs nothing).
    /// Infinite entries where even those say nothing.
    pub fn pinned_covariance(&self) -> Matrix3<f64> {
        self.turns[..2].iter().map(|t| t.axis * t.axis.transpose() * t.sigma_rad.powi(2)).sum()
    }
}

/// The expected length of a zero-mean Gaussian turn with covariance `cov` (rad^2), radians:
/// `E |x|` over its principal deviations, a midpoint rule over +-6 sigma on each (infinite where
/// a deviation is).
pub fn expected_turn(cov: &Matrix3<f64>) -> f64 {
    expected_turn_within(cov, f64::INFINITY)
}

/// [`expected_turn`] of what is left of the Gaussian where every turn about its principal axes
/// over `cut_rad` is ruled out (as a mask rules out a large turn): each principal deviation's
/// range is +-6 sigma or +-`cut_rad`, whichever is narrower (infinite where a deviation is,
/// cut or not).
pub fn expected_turn_within(cov: &Matrix3<f64>, cut_rad: f64) -> f64 {
    if !cov.iter().all(|v| v.is_finite()) {
        return f64::INFINITY;
    }
    let s = SymmetricEigen::new(*cov).eigenvalues.map(|v| v.max(0.0).sqrt());
    // Each deviation's half range in its own sigmas (a zero deviation adds nothing anywhere).
    let half = s.map(|si| if si > 0.0 { (cut_rad / si).min(6.0) } else { 6.0 });
    let n = 96;
    let at = |h: f64, i: usize| h * (-1.0 + 2.0 * (i as f64 + 0.5) / n as f64);
    let (mut sum, mut weight) = (0.0, 0.0);
    for i in 0..n {
        let x = at(half[0], i);
        for j in 0..n {
            let y = at(half[1], j);
            for k in 0..n {
                let z = at(half[2], k);
                let w = (-0.5 * (x * x + y * y + z * z)).exp();
                sum += w * Vector3::new(s[0] * x, s[1] * y, s[2] * z).norm();
                weight += w;
            }
        }
    }
    sum / weight
}

/// The floor under the paper's calibrated rotation error of one frame, radians. The metric
/// scores `|log(R_corr^T R_gt)|` with `R_corr = R_est R0_est^T R0_gt`: for small errors the
/// difference of the two frames' errors in the target's own axes, `eps - eps0`. An estimator
/// unbiased on each frame, whose frames' errors are independent (no motion model ties them),
/// has at least the sum of the two frames' bounds as that difference's covariance (each turned
/// into the target's axes by its true rotation); this is the expected size of a Gaussian with
/// that covariance, each frame's loosest turn taken as exact ([`PoseBound::pinned_covariance`]).
pub fn calibrated_floor(
    first: &PoseBound,
    first_truth: &Pose,
    frame: &PoseBound,
    truth: &Pose,
) -> f64 {
    let body = |b: &PoseBound, t: &Pose| {
        let r = t.rotation.to_rotation_matrix();
        r.matrix().transpose() * b.pinned_covariance() * r.matrix()
    };
    expected_turn(&(body(first, first_truth) + body(frame, truth)))
}

/// The drawn depth at every pixel (infinite off the drawing), metres.
fn drawn_depth(r: &mut SilhouetteRenderer, frame: &PerceptionFrame, pose: &Pose) -> Vec<f64> {
    let mut mask = Vec::new();
    r.draw(pose, &frame.intrinsics, 0, &mut mask);
    (0..mask.len())
        .map(|i| match mask[i] {
            TARGET => r.surface_depth(i).map_or(f64::INFINITY, f64::from),
            _ => f64::INFINITY,
        })
        .collect()
}

/// `pose` moved by `x`: turned by `x[0..3]` (rotation vector) about the target's origin, then
/// shifted by `x[3..6]`, camera axes.
fn moved(pose: &Pose, x: &Vector6<f64>) -> Pose {
    Pose::from_parts(
        Translation3::from(pose.translation.vector + x.fixed_rows::<3>(3)),
        UnitQuaternion::from_scaled_axis(x.fixed_rows::<3>(0).into_owned()) * pose.rotation,
    )
}

/// The Cramer-Rao bound of `frame`'s depth on the pose of `mesh` (as the camera sees it: lab
/// metres) at `truth`, with `sigma(z)` the depth noise's standard deviation at depth `z`
/// (metres). Refuses a mesh that cannot be drawn and a frame in which the drawing at the truth
/// meets fewer than 6 pixels.
pub fn depth_bound(
    frame: &PerceptionFrame,
    mesh: &Mesh,
    truth: &Pose,
    sigma: impl Fn(f64) -> f64,
) -> Result<PoseBound, PerceptionError> {
    frame.validate()?;
    let mut r = SilhouetteRenderer::new(mesh)?;
    let at_truth = drawn_depth(&mut r, frame, truth);
    let target_pixels = (0..at_truth.len()).filter(|&i| frame.is_target(i)).count();
    let measured = measuring_pixels(frame, &at_truth, &sigma);
    let residual = |i: usize| (f64::from(frame.depth_m[i]) - at_truth[i]) / sigma(at_truth[i]);
    let steps =
        [TURN_STEP_RAD, TURN_STEP_RAD, TURN_STEP_RAD, SHIFT_STEP_M, SHIFT_STEP_M, SHIFT_STEP_M];
    let mut slope = vec![Vector6::<f64>::zeros(); measured.len()];
    let mut keep = vec![true; measured.len()];
    for (j, step) in steps.iter().enumerate() {
        let mut x = Vector6::zeros();
        x[j] = *step;
        let plus = drawn_depth(&mut r, frame, &moved(truth, &x));
        let minus = drawn_depth(&mut r, frame, &moved(truth, &(-x)));
        for (k, &i) in measured.iter().enumerate() {
            let d = plus[i] - minus[i];
            // A smooth surface moves a fraction of the noise under these steps; more is a jump.
            if !d.is_finite() || d.abs() > (0.2 * sigma(at_truth[i])).max(1e-4) {
                keep[k] = false;
            } else {
                slope[k][j] = d / (2.0 * step);
            }
        }
    }
    let mut fisher = Matrix6::<f64>::zeros();
    let mut chi2 = 0.0;
    let mut counted = 0usize;
    for (k, &i) in measured.iter().enumerate().filter(|(k, _)| keep[*k]) {
        let s2 = sigma(at_truth[i]).powi(2);
        fisher += slope[k] * slope[k].transpose() / s2;
        chi2 += residual(i).powi(2);
        counted += 1;
    }
    if counted < 6 {
        return Err(PerceptionError::BadFrame(format!(
            "{counted} pixels measure the target's surface at the given pose: too few for a bound"
        )));
    }
    // The covariance (Fisher's inverse; a direction the pixels say nothing of gets an infinite
    // variance), its rotation block and that block's principal turns.
    let eig = SymmetricEigen::new(fisher);
    let floor = eig.eigenvalues.max() * 1e-14;
    let mut cov = Matrix6::<f64>::zeros();
    for k in 0..6 {
        let v = eig.eigenvectors.column(k);
        let info = eig.eigenvalues[k];
        let var = if info > floor { 1.0 / info } else { 1e12 };
        cov += v * v.transpose() * var;
    }
    let rot: Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
    let rot_eig = SymmetricEigen::new(rot);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| rot_eig.eigenvalues[a].total_cmp(&rot_eig.eigenvalues[b]));
    let turns = order.map(|k| {
        let var = rot_eig.eigenvalues[k].max(0.0);
        Turn {
            axis: rot_eig.eigenvectors.column(k).into_owned(),
            sigma_rad: if var >= 1e11 { f64::INFINITY } else { var.sqrt() },
        }
    });
    Ok(PoseBound {
        target_pixels,
        counted,
        chi2_per_pixel: chi2 / counted as f64,
        turns,
        centroid: centroid(frame, &measured, &at_truth),
        measuring_pixels: measured,
    })
}

/// The frame's target pixels that measure the target's surface at the drawing `at_truth`.
fn measuring_pixels(
    frame: &PerceptionFrame,
    at_truth: &[f64],
    sigma: &impl Fn(f64) -> f64,
) -> Vec<usize> {
    (0..at_truth.len())
        .filter(|&i| frame.is_target(i) && at_truth[i].is_finite())
        .filter(|&i| (f64::from(frame.depth_m[i]) - at_truth[i]).abs() < 5.0 * sigma(at_truth[i]))
        .collect()
}

fn centroid(frame: &PerceptionFrame, pixels: &[usize], depth: &[f64]) -> Vector3<f64> {
    let k = frame.intrinsics;
    let w = k.width as usize;
    let sum = pixels
        .iter()
        .map(|&i| {
            let (x, y) = k.unproject((i % w) as f64, (i / w) as f64);
            Vector3::new(x * depth[i], y * depth[i], depth[i])
        })
        .sum::<Vector3<f64>>();
    sum / pixels.len().max(1) as f64
}

/// What the mask would charge the pose `truth` turned by `turn_rad` about `axis` (camera frame)
/// through the measured surface's centroid (so the surface stays where the depth puts it; the
/// pivot changes no rotation bound): the drawn pixels off the mask where the frame has no depth,
/// plus the pixels measuring the target's surface ([`PoseBound::measuring`]) the drawing leaves
/// uncovered. 0 where the mask and those pixels cannot tell the turned pose from the truth.
pub fn mask_room(
    frame: &PerceptionFrame,
    mesh: &Mesh,
    truth: &Pose,
    bound: &PoseBound,
    axis: &Vector3<f64>,
    turn_rad: f64,
) -> Result<usize, PerceptionError> {
    frame.validate()?;
    let mut r = SilhouetteRenderer::new(mesh)?;
    let pivot = bound.centroid;
    let turn = UnitQuaternion::from_scaled_axis(axis.normalize() * turn_rad);
    let t = turn * (truth.translation.vector - pivot) + pivot;
    let pose = Pose::from_parts(Translation3::from(t), turn * truth.rotation);
    let mut drawn = Vec::new();
    r.draw(&pose, &frame.intrinsics, 0, &mut drawn);
    let off_mask = (0..drawn.len())
        .filter(|&i| {
            let z = frame.depth_m[i];
            drawn[i] == TARGET && !frame.in_silhouette(i) && !(z.is_finite() && z > 0.0)
        })
        .count();
    let uncovered =
        bound.measuring_pixels.iter().filter(|&&i| drawn.get(i) != Some(&TARGET)).count();
    Ok(off_mask + uncovered)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn bound(turns: [(Vector3<f64>, f64); 3]) -> PoseBound {
        PoseBound {
            target_pixels: 0,
            counted: 0,
            chi2_per_pixel: 1.0,
            turns: turns.map(|(axis, sigma_rad)| Turn { axis, sigma_rad }),
            centroid: Vector3::zeros(),
            measuring_pixels: Vec::new(),
        }
    }

    #[test]
    fn the_expected_turn_is_the_gaussians_mean_length() {
        let s = 0.01;
        // Maxwell's mean for three equal deviations, the half-normal's for one.
        let three = expected_turn(&(Matrix3::identity() * s * s));
        assert!((three / (2.0 * s * (2.0 / PI).sqrt()) - 1.0).abs() < 1e-3, "{three}");
        let one = expected_turn(&Matrix3::from_diagonal(&Vector3::new(s * s, 0.0, 0.0)));
        assert!((one / (s * (2.0 / PI).sqrt()) - 1.0).abs() < 1e-3, "{one}");
        let unbounded = Matrix3::from_diagonal(&Vector3::new(s * s, f64::INFINITY, 0.0));
        assert_eq!(expected_turn(&unbounded), f64::INFINITY);
        // Cut at one sigma: the truncated half-normal's mean, sigma sqrt(2/pi) (1 - e^-1/2) /
        // erf(1/sqrt 2) = 0.45986 sigma.
        let one_axis = Matrix3::from_diagonal(&Vector3::new(s * s, 0.0, 0.0));
        let cut = expected_turn_within(&one_axis, s);
        assert!((cut / (0.45986 * s) - 1.0).abs() < 1e-3, "{cut}");
        assert_eq!(expected_turn_within(&one_axis, 7.0 * s), one);
    }

    #[test]
    fn the_calibrated_floor_adds_both_frames_bounds_in_the_targets_own_axes() {
        // Each frame pins its camera x turn to 1 mrad and its y turn to 3 mrad, and says nothing
        // of its roll (taken as exact). The second view is the first turned 90 deg about the line
        // of sight, so in the target's axes their loose turns cross: the sum is 10e-6 rad^2 on
        // both tilts (2e-6 and 18e-6 if the frames' camera axes were added as they are).
        let b = bound([(Vector3::x(), 1e-3), (Vector3::y(), 3e-3), (Vector3::z(), f64::INFINITY)]);
        let first = Pose::identity();
        let turned = Pose::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_euler_angles(0.0, 0.0, FRAC_PI_2),
        );
        let want = (10e-6f64).sqrt() * (PI / 2.0).sqrt();
        let got = calibrated_floor(&b, &first, &b, &turned);
        assert!((got / want - 1.0).abs() < 2e-3, "{got} vs {want}");
        // The same view twice: twice the one frame's covariance.
        let same = calibrated_floor(&b, &first, &b, &first);
        assert!((same / (2f64.sqrt() * b.pinned_mean_rad()) - 1.0).abs() < 2e-3, "{same}");
        assert!((got / same - 1.0).abs() > 0.05, "{got} {same}");
    }
}
