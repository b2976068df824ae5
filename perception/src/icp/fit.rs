//! Render-and-compare fitting: a pose moved to where the drawn target explains the frame best
//! ([`super::compare::Comparer::disagreement`]), by argmin's Nelder-Mead simplex search over the
//! six pose parameters.
//!
//! Why a derivative-free search on top of the Gauss-Newton steps ([`super::align`] and the
//! pixel-wise steps of [`super::compare`]): those minimise the depth residuals of the pixels or
//! points they pair and know nothing of the silhouette, so on a small view of a stereo camera's
//! noisy depth (a 2 m target at 10 m seen end on: 250 target pixels) they slid 5-20 deg off the
//! true pose toward one that fits fewer, quieter pixels. The disagreement counts every pixel
//! the drawing and the frame do not share, so it is lowest near the truth; it is a sum of
//! steps and truncated quadratics with no useful derivative, hence the simplex.

use super::compare::Comparer;
use crate::PerceptionFrame;
use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use hitl_hal::Pose;
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use std::cell::RefCell;

/// The first simplex's size and the search's length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitSteps {
    /// The simplex's first turn about each camera axis, radians.
    pub turn_rad: f64,
    /// Its first shift along each camera axis, metres.
    pub shift_m: f64,
    /// Simplex iterations at most (each draws the target once or twice; a shrink, seven times).
    pub iters: u64,
}

/// The simplex stops when its vertices' disagreements differ by less than this (target pixels).
const SETTLED_PIXELS: f64 = 0.02;

/// The pose parameters around a start: a turn (rotation vector, in `turn_rad` units) about the
/// target's origin and a shift (in `shift_m` units), both in the camera frame.
struct Problem<'a> {
    comparer: RefCell<&'a mut Comparer>,
    frame: &'a PerceptionFrame,
    start: Pose,
    steps: FitSteps,
    tol: f64,
    far_m: f64,
}

impl Problem<'_> {
    fn pose(&self, x: &[f64]) -> Pose {
        let turn = Vector3::new(x[0], x[1], x[2]) * self.steps.turn_rad;
        let shift = Vector3::new(x[3], x[4], x[5]) * self.steps.shift_m;
        Pose::from_parts(
            Translation3::from(self.start.translation.vector + shift),
            UnitQuaternion::from_scaled_axis(turn) * self.start.rotation,
        )
    }
}

impl CostFunction for Problem<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> Result<f64, argmin::core::Error> {
        let pose = self.pose(x);
        Ok(self.comparer.borrow_mut().disagreement(self.frame, &pose, self.tol, self.far_m))
    }
}

/// `start` moved to the pose of least disagreement the simplex finds, and that disagreement;
/// `start` itself if the search could not run or found nothing better. The comparer must be
/// prepared for `frame` ([`Comparer::prepare`]).
pub fn fit(
    comparer: &mut Comparer,
    frame: &PerceptionFrame,
    start: &Pose,
    steps: FitSteps,
    tol: f64,
    far_m: f64,
) -> (Pose, f64) {
    let problem =
        Problem { comparer: RefCell::new(comparer), frame, start: *start, steps, tol, far_m };
    let at_start = problem.cost(&vec![0.0; 6]).unwrap_or(f64::INFINITY);
    // The start and one step along each parameter.
    let simplex: Vec<Vec<f64>> =
        (0..=6).map(|k| (0..6).map(|j| if j + 1 == k { 1.0 } else { 0.0 }).collect()).collect();
    let Ok(solver) = NelderMead::new(simplex).with_sd_tolerance(SETTLED_PIXELS) else {
        return (*start, at_start);
    };
    let Ok(result) = Executor::new(problem, solver).configure(|s| s.max_iters(steps.iters)).run()
    else {
        return (*start, at_start);
    };
    let best = result.state.best_param.as_ref();
    match (best, result.problem.problem.as_ref()) {
        (Some(x), Some(p)) if result.state.best_cost < at_start => {
            (p.pose(x), result.state.best_cost)
        }
        _ => (*start, at_start),
    }
}
