//! PnP with RANSAC: the pose that most 2D-3D matches agree with. Each hypothesis is four random
//! matches refined by Gauss-Newton from the tracked pose ([`crate::pnp::refine_pnp`]); the one
//! with most matches within the pixel tolerance is refined on all of them.

use crate::pnp::refine_pnp;
use hitl_hal::{Intrinsics, Pose};
use nalgebra::Vector3;

/// The pose the matches agree with, how many do, and their RMS reprojection error (pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Consensus {
    pub pose: Pose,
    pub inliers: usize,
    pub rms_px: f64,
}

/// Matches of `body` (model frame, metres) at `pixels` within `tol_px` of where `pose` puts
/// them (in front of the camera): their indices and squared errors.
fn inliers(
    body: &[Vector3<f64>],
    pixels: &[(f64, f64)],
    k: &Intrinsics,
    pose: &Pose,
    tol_px: f64,
) -> (Vec<usize>, f64) {
    let mut idx = Vec::new();
    let mut sq = 0.0;
    for (i, (p, (u, v))) in body.iter().zip(pixels).enumerate() {
        let q = pose * nalgebra::Point3::from(*p);
        if q.z <= 0.0 {
            continue;
        }
        let (du, dv) = (k.fx * q.x / q.z + k.cx - u, k.fy * q.y / q.z + k.cy - v);
        let e = du * du + dv * dv;
        if e <= tol_px * tol_px {
            idx.push(i);
            sq += e;
        }
    }
    (idx, sq)
}

/// The consensus of the matches `body[i]` at `pixels[i]`, hypotheses from `prior` (the tracked
/// pose). `None` with fewer than 4 matches or when no hypothesis is in front of the camera.
/// Deterministic: the samples come from `seed`.
pub fn pnp_ransac(
    body: &[Vector3<f64>],
    pixels: &[(f64, f64)],
    k: &Intrinsics,
    prior: &Pose,
    iterations: usize,
    tol_px: f64,
    seed: u64,
) -> Option<Consensus> {
    let n = body.len();
    if n < 4 || pixels.len() != n {
        return None;
    }
    let mut state = seed | 1;
    let mut rand = move |m: usize| {
        // xorshift64*
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 33) as usize % m
    };
    let (mut best, mut best_in) = (*prior, inliers(body, pixels, k, prior, tol_px).0);
    for _ in 0..iterations {
        let mut pick = [0usize; 4];
        let mut m = 0;
        while m < 4 {
            let c = rand(n);
            if !pick[..m].contains(&c) {
                pick[m] = c;
                m += 1;
            }
        }
        let b: Vec<Vector3<f64>> = pick.iter().map(|&i| body[i]).collect();
        let p: Vec<(f64, f64)> = pick.iter().map(|&i| pixels[i]).collect();
        let Ok(pose) = refine_pnp(&b, &p, k, prior) else { continue };
        let (idx, _) = inliers(body, pixels, k, &pose, tol_px);
        if idx.len() > best_in.len() {
            best = pose;
            best_in = idx;
        }
    }
    // Refined on every inlier, twice (the inliers of the refined pose, then again).
    for _ in 0..2 {
        if best_in.len() < 4 {
            break;
        }
        let b: Vec<Vector3<f64>> = best_in.iter().map(|&i| body[i]).collect();
        let p: Vec<(f64, f64)> = best_in.iter().map(|&i| pixels[i]).collect();
        let Ok(pose) = refine_pnp(&b, &p, k, &best) else { break };
        let (idx, _) = inliers(body, pixels, k, &pose, tol_px);
        if idx.len() < best_in.len() {
            break;
        }
        best = pose;
        best_in = idx;
    }
    let (idx, sq) = inliers(body, pixels, k, &best, tol_px);
    if idx.is_empty() {
        return None;
    }
    Some(Consensus { pose: best, inliers: idx.len(), rms_px: (sq / idx.len() as f64).sqrt() })
}
