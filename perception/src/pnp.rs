//! Perspective-n-point: the pose of known 3D points from their pixels. Direct linear transform on
//! normalised data for a first guess, then Gauss-Newton on the reprojection error.

use crate::pose::from_rt;
use crate::PerceptionError;
use hitl_hal::{Intrinsics, Pose};
use nalgebra::{DMatrix, Matrix3, SymmetricEigen, Vector3, Vector6};

/// Pose of the body whose points `body` (body frame, metres) appear at `pixels` (u, v).
/// Needs at least 6 points, not all on one plane.
pub fn solve_pnp(
    body: &[Vector3<f64>],
    pixels: &[(f64, f64)],
    k: &Intrinsics,
) -> Result<Pose, PerceptionError> {
    if body.len() != pixels.len() {
        return Err(PerceptionError::BadInput(format!(
            "PnP: {} 3D points but {} pixels",
            body.len(),
            pixels.len()
        )));
    }
    if body.len() < 6 {
        return Err(PerceptionError::BadInput(format!(
            "PnP needs at least 6 points, got {}",
            body.len()
        )));
    }
    if body.iter().any(|p| !p.iter().all(|c| c.is_finite()))
        || pixels.iter().any(|(u, v)| !(u.is_finite() && v.is_finite()))
    {
        return Err(PerceptionError::BadInput("PnP: non-finite input".into()));
    }
    let rays: Vec<(f64, f64)> = pixels.iter().map(|(u, v)| k.unproject(*u, *v)).collect();
    let init = dlt(body, &rays)?;
    Ok(refine(body, &rays, init))
}

fn dlt(body: &[Vector3<f64>], rays: &[(f64, f64)]) -> Result<Pose, PerceptionError> {
    let n = body.len();
    let c = body.iter().sum::<Vector3<f64>>() / n as f64;
    let s = (body.iter().map(|p| (p - c).norm()).sum::<f64>() / n as f64).max(1e-12);
    let mut a = DMatrix::<f64>::zeros(2 * n, 12);
    for (i, (p, (x, y))) in body.iter().zip(rays).enumerate() {
        let q = (p - c) / s;
        let h = [q.x, q.y, q.z, 1.0];
        for j in 0..4 {
            a[(2 * i, j)] = h[j];
            a[(2 * i, 8 + j)] = -x * h[j];
            a[(2 * i + 1, 4 + j)] = h[j];
            a[(2 * i + 1, 8 + j)] = -y * h[j];
        }
    }
    let ata = a.transpose() * &a;
    let eig = SymmetricEigen::new(ata);
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .ok_or_else(|| PerceptionError::BadInput("PnP: no solution".into()))?;
    let sorted = {
        let mut v: Vec<f64> = eig.eigenvalues.iter().copied().collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v
    };
    if sorted[1] <= 1e-12 * sorted[11].max(1e-300) {
        return Err(PerceptionError::BadInput(
            "PnP: degenerate points (coplanar or repeated): no unique pose".into(),
        ));
    }
    let p = eig.eigenvectors.column(imin);
    let m = Matrix3::new(p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10]);
    let mut t = Vector3::new(p[3], p[7], p[11]);
    let svd = m.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(PerceptionError::BadInput("PnP: SVD failed".into()));
    };
    let mut lambda = svd.singular_values.mean();
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        r = -r;
        lambda = -lambda;
    }
    t /= lambda;
    // Undo the normalisation: x ~ R (p - c)/s + t  =>  R p + (s t - R c), scaled by s.
    let t_body = s * t - r * c;
    // The sign of the null vector is fixed by det(R) = +1 (which also puts the points in front).
    Ok(from_rt(&r, &t_body))
}

/// Pose of the body whose points `body` appear at `pixels`, by Gauss-Newton on the reprojection
/// error from `init` (no linear first guess): for few points (4 or more) near a known pose, as a
/// RANSAC hypothesis from a tracked pose is. Points behind the camera at `init` make no sense of
/// the cost; the caller checks the answer.
pub fn refine_pnp(
    body: &[Vector3<f64>],
    pixels: &[(f64, f64)],
    k: &Intrinsics,
    init: &Pose,
) -> Result<Pose, PerceptionError> {
    if body.len() != pixels.len() || body.len() < 3 {
        return Err(PerceptionError::BadInput(format!(
            "PnP refinement: {} 3D points, {} pixels (at least 3 pairs)",
            body.len(),
            pixels.len()
        )));
    }
    let rays: Vec<(f64, f64)> =
        pixels.iter().map(|(u, v)| ((u - k.cx) / k.fx, (v - k.cy) / k.fy)).collect();
    Ok(refine(body, &rays, *init))
}

fn residuals(body: &[Vector3<f64>], rays: &[(f64, f64)], t: &Pose) -> Vec<f64> {
    let r = t.rotation.to_rotation_matrix();
    let tr = t.translation.vector;
    let mut out = Vec::with_capacity(2 * body.len());
    for (p, (x, y)) in body.iter().zip(rays) {
        let q = r * p + tr;
        out.push(q.x / q.z - x);
        out.push(q.y / q.z - y);
    }
    out
}

fn refine(body: &[Vector3<f64>], rays: &[(f64, f64)], init: Pose) -> Pose {
    let mut t = init;
    let cost = |t: &Pose| residuals(body, rays, t).iter().map(|e| e * e).sum::<f64>();
    let mut c0 = cost(&t);
    for _ in 0..20 {
        let r0 = residuals(body, rays, &t);
        let m = r0.len();
        let mut j = DMatrix::<f64>::zeros(m, 6);
        let h = 1e-7;
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let tk = perturb(&t, &d);
            let rk = residuals(body, rays, &tk);
            for i in 0..m {
                j[(i, k)] = (rk[i] - r0[i]) / h;
            }
        }
        let jtj = j.transpose() * &j;
        let jtr = j.transpose() * DMatrix::from_column_slice(m, 1, &r0);
        let Some(step) = jtj.cholesky().map(|ch| ch.solve(&(-jtr))) else {
            break;
        };
        let d = Vector6::from_iterator(step.iter().copied());
        let cand = perturb(&t, &d);
        let c1 = cost(&cand);
        if c1.is_nan() || c1 >= c0 {
            break;
        }
        t = cand;
        let done = c0 - c1 < 1e-18;
        c0 = c1;
        if done {
            break;
        }
    }
    t
}

/// `t` moved by the twist `d` (rotation vector, then translation), applied on the camera side.
fn perturb(t: &Pose, d: &Vector6<f64>) -> Pose {
    Pose::new(Vector3::new(d[3], d[4], d[5]), Vector3::new(d[0], d[1], d[2])) * t
}
