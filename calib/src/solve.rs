//! The robot-world-hand-eye solver: where the camera is on the flange (`X`, flange -> camera)
//! and where the board is in the arm's base frame (`Z`, base -> board), from views of the board
//! taken at known flange poses (`A_i`, base -> flange, forward kinematics).
//!
//! 1. Per view, the board's pose in the camera from its corners: a homography (direct linear
//!    transform on normalised points) decomposed into a rotation and translation, then
//!    Gauss-Newton on the view's reprojection error ([`planar_pose`]). (perception's `solve_pnp`
//!    needs points off one plane, so it does not fit a flat board.)
//! 2. Shah's closed form for `A_i X = Z B_i` (`B_i` = board -> camera, the inverse of step 1's
//!    pose): the rotations from the null vector of the stacked Kronecker system
//!    `(I (x) R_A) vec(R_X) = (R_B^T (x) I) vec(R_Z)`, each projected onto SO(3); then the
//!    translations by linear least squares in each view's camera frame ([`shah`]).
//! 3. A joint Levenberg-Marquardt refinement of `X` and `Z` (12 parameters, local increments
//!    `X exp(d)`) on every corner's reprojection error through `X^-1 A_i^-1 Z`; written here on
//!    nalgebra (the `levenberg-marquardt` crate is built on an older nalgebra than the
//!    workspace's). The covariance of the parameters is `s^2 (J^T J)^-1` with `s^2` the residual
//!    variance; every reported uncertainty is propagated from it ([`refine`]).
//!
//! Intrinsics are taken as known (the camera's own calibration), pixels in OpenCV's convention
//! (integer coordinates at pixel centres).

use crate::detect::Corner;
use hitl_hal::{Intrinsics, Pose};
use nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Point3, SMatrix, Translation3, UnitQuaternion, Vector3,
};

/// One view: the flange pose it was taken at and the board corners seen in it.
#[derive(Debug, Clone)]
pub struct View {
    /// Base -> flange (forward kinematics of the joints at exposure).
    pub base_flange: Pose,
    pub corners: Vec<Corner>,
}

/// Why no solution was accepted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("{0}")]
    TooFewViews(String),
    #[error("{0}")]
    PoorConditioning(String),
    #[error("{0}")]
    PoorResiduals(String),
}

/// What a solution must meet to be accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Acceptance {
    /// Fewest views with the board detected.
    pub min_views: usize,
    /// Fewest corners in a view for it to count.
    pub min_corners_per_view: usize,
    /// Largest RMS reprojection error over all corners, pixels.
    pub max_rms_px: f64,
    /// Largest RMS of any one view, pixels.
    pub max_view_rms_px: f64,
    /// Largest one-sigma translation uncertainty (camera mount or board), millimetres.
    pub max_sigma_mm: f64,
    /// Largest one-sigma rotation uncertainty, degrees.
    pub max_sigma_deg: f64,
    /// Smallest spread of the views' relative rotations about the second-best axis, degrees.
    pub min_rotation_spread_deg: f64,
}

impl Default for Acceptance {
    fn default() -> Self {
        Self {
            min_views: 10,
            min_corners_per_view: 16,
            max_rms_px: 1.0,
            max_view_rms_px: 2.0,
            max_sigma_mm: 0.5,
            max_sigma_deg: 0.05,
            min_rotation_spread_deg: 10.0,
        }
    }
}

/// One-sigma uncertainties of a recovered pose.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sigma {
    /// Translation, millimetres (root of the trace of its covariance).
    pub mm: f64,
    /// Rotation, degrees (root of the trace of its covariance).
    pub deg: f64,
}

/// An accepted (or inspected) solution.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Flange -> camera (OpenCV axes).
    pub camera_mount: Pose,
    /// Base -> board.
    pub board_in_base: Pose,
    /// The closed form's estimate before refinement (same frames).
    pub shah_camera_mount: Pose,
    pub shah_board_in_base: Pose,
    pub rms_px: f64,
    pub view_rms_px: Vec<f64>,
    pub camera_sigma: Sigma,
    pub board_sigma: Sigma,
    /// Covariance of the 12 local increments (X: translation, rotation; Z: same).
    pub covariance: SMatrix<f64, 12, 12>,
    pub iterations: usize,
    pub corners: usize,
}

/// Where `k` (through its lens) sees `p`, in front of the camera.
fn project(k: &Intrinsics, p: &Point3<f64>) -> Option<(f64, f64)> {
    (p.z > 1e-6).then(|| k.project(p.x, p.y, p.z))
}

fn increment(d: &[f64]) -> Pose {
    Isometry3::new(Vector3::new(d[0], d[1], d[2]), Vector3::new(d[3], d[4], d[5]))
}

/// Rotation of `r` projected onto SO(3) (nearest in Frobenius norm).
fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    u * d * vt
}

fn iso(r: &Matrix3<f64>, t: &Vector3<f64>) -> Pose {
    Isometry3::from_parts(Translation3::from(*t), UnitQuaternion::from_matrix(r))
}

/// The board's pose in the camera (board -> camera) from one view's corners, or `None` when
/// they do not determine one (fewer than 4, or degenerate).
pub fn planar_pose(corners: &[Corner], k: &Intrinsics) -> Option<Pose> {
    if corners.len() < 4 {
        return None;
    }
    let n = corners.len();
    let c = corners.iter().map(|c| c.board.coords.xy()).sum::<nalgebra::Vector2<f64>>() / n as f64;
    let s = (corners.iter().map(|p| (p.board.coords.xy() - c).norm()).sum::<f64>() / n as f64)
        .max(1e-12);
    let mut a = DMatrix::<f64>::zeros(2 * n, 9);
    for (i, p) in corners.iter().enumerate() {
        let q = (p.board.coords.xy() - c) / s;
        // The corner's ray, the lens's distortion removed: the homography is a pinhole's.
        let (x, y) = k.unproject(p.pixel.0, p.pixel.1);
        let h = [q.x, q.y, 1.0];
        for j in 0..3 {
            a[(2 * i, j)] = h[j];
            a[(2 * i, 6 + j)] = -x * h[j];
            a[(2 * i + 1, 3 + j)] = h[j];
            a[(2 * i + 1, 6 + j)] = -y * h[j];
        }
    }
    let eig = (a.transpose() * &a).symmetric_eigen();
    let imin = eig.eigenvalues.imin();
    let v = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
    // Undo the normalisation: board (x, y) -> q = (x - c) / s.
    let norm = Matrix3::new(1.0 / s, 0.0, -c.x / s, 0.0, 1.0 / s, -c.y / s, 0.0, 0.0, 1.0);
    let h = hn * norm;
    let (h1, h2, h3) =
        (h.column(0).into_owned(), h.column(1).into_owned(), h.column(2).into_owned());
    let scale = 2.0 / (h1.norm() + h2.norm());
    if !scale.is_finite() {
        return None;
    }
    let sign = if h3.z * scale < 0.0 { -1.0 } else { 1.0 };
    let (r1, r2, t) = (h1 * scale * sign, h2 * scale * sign, h3 * scale * sign);
    let r = nearest_rotation(&Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]));
    let mut pose = iso(&r, &t);
    // Gauss-Newton on this view's reprojection error.
    for _ in 0..20 {
        let (j, res) = numeric_jacobian::<6>(
            &|d: &[f64]| view_residuals(corners, k, &(pose * increment(d))),
            &[0.0; 6],
            res_len(corners),
        )?;
        let jtj = j.transpose() * &j;
        let step = jtj.cholesky()?.solve(&(-(j.transpose() * &res)));
        pose *= increment(step.as_slice());
        if step.norm() < 1e-12 {
            break;
        }
    }
    Some(pose)
}

fn res_len(c: &[Corner]) -> usize {
    2 * c.len()
}

fn view_residuals(corners: &[Corner], k: &Intrinsics, cam_board: &Pose) -> Option<Vec<f64>> {
    let mut r = Vec::with_capacity(2 * corners.len());
    for c in corners {
        let (u, v) = project(k, &(cam_board * c.board))?;
        r.push(u - c.pixel.0);
        r.push(v - c.pixel.1);
    }
    Some(r)
}

/// Forward-difference Jacobian of `f` at `x0` (residuals of length `m`), and `f(x0)`.
fn numeric_jacobian<const N: usize>(
    f: &dyn Fn(&[f64]) -> Option<Vec<f64>>,
    x0: &[f64; N],
    m: usize,
) -> Option<(DMatrix<f64>, DVector<f64>)> {
    let r0 = DVector::from_vec(f(x0)?);
    if r0.len() != m {
        return None;
    }
    let mut j = DMatrix::<f64>::zeros(m, N);
    let h = 1e-7;
    for p in 0..N {
        let mut x = *x0;
        x[p] += h;
        let r = DVector::from_vec(f(&x)?);
        j.set_column(p, &((r - &r0) / h));
    }
    Some((j, r0))
}

/// Shah's closed form for `A_i X = Z B_i` (all rigid transforms): `(X, Z)`.
pub fn shah(a: &[Pose], b: &[Pose]) -> Option<(Pose, Pose)> {
    let n = a.len();
    if n < 3 || b.len() != n {
        return None;
    }
    // Column-major vec: vec(R_A R_X) = (I (x) R_A) vec(R_X); vec(R_Z R_B) = (R_B^T (x) I) vec(R_Z).
    let mut m = SMatrix::<f64, 18, 18>::zeros();
    for (ai, bi) in a.iter().zip(b) {
        let ra = ai.rotation.to_rotation_matrix().into_inner();
        let rb = bi.rotation.to_rotation_matrix().into_inner();
        let mut row = SMatrix::<f64, 9, 18>::zeros();
        let i3 = Matrix3::<f64>::identity();
        let k1 = i3.kronecker(&ra);
        let k2 = rb.transpose().kronecker(&i3);
        row.fixed_view_mut::<9, 9>(0, 0).copy_from(&k1);
        row.fixed_view_mut::<9, 9>(0, 9).copy_from(&(-k2));
        m += row.transpose() * row;
    }
    let eig = m.symmetric_eigen();
    let v = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
    let rx = Matrix3::from_column_slice(&v.as_slice()[0..9]);
    let rz = Matrix3::from_column_slice(&v.as_slice()[9..18]);
    // Fix the null vector's scale and sign so that both are rotations.
    let d = rx.determinant();
    let alpha = d.signum() * d.abs().cbrt();
    if alpha.abs() < 1e-12 {
        return None;
    }
    let rx = nearest_rotation(&(rx / alpha));
    let rz = nearest_rotation(&(rz / alpha));
    // Translations, written in each view's camera frame (as OpenCV writes Shah's method), with
    // C_i = B_i^-1 (the board's pose in the camera), Z' = Z^-1, X' = X^-1:
    // C_i Z' = X' A_i^-1, so R_Ci t_Z' - t_X' = R_X' t_(A_i^-1) - t_Ci.
    let rxi = rx.transpose();
    let mut lhs = DMatrix::<f64>::zeros(3 * n, 6);
    let mut rhs = DVector::<f64>::zeros(3 * n);
    for (i, (ai, bi)) in a.iter().zip(b).enumerate() {
        let c = bi.inverse();
        let rc = c.rotation.to_rotation_matrix().into_inner();
        lhs.view_mut((3 * i, 0), (3, 3)).copy_from(&rc);
        lhs.view_mut((3 * i, 3), (3, 3)).copy_from(&(-Matrix3::identity()));
        let r = rxi * ai.inverse().translation.vector - c.translation.vector;
        rhs.rows_mut(3 * i, 3).copy_from(&r);
    }
    let sol = lhs.svd(true, true).solve(&rhs, 1e-12).ok()?;
    let tzi = Vector3::new(sol[0], sol[1], sol[2]);
    let txi = Vector3::new(sol[3], sol[4], sol[5]);
    // t_X = -R_X t_X', t_Z = -R_Z t_Z'.
    let tx = -(rx * txi);
    let tz = -(rz * tzi);
    Some((iso(&rx, &tx), iso(&rz, &tz)))
}

fn all_residuals(views: &[View], k: &Intrinsics, x: &Pose, z: &Pose) -> Option<Vec<f64>> {
    let mut r = Vec::new();
    let xinv = x.inverse();
    for v in views {
        let cam_board = xinv * v.base_flange.inverse() * z;
        r.extend(view_residuals(&v.corners, k, &cam_board)?);
    }
    Some(r)
}

/// Rotation spread of the views: the singular values (degrees) of the stacked rotation vectors
/// of every view's flange rotation relative to the first, largest first. Hand-eye needs two
/// independent axes: the second value is what [`Acceptance::min_rotation_spread_deg`] checks.
pub fn rotation_spread_deg(views: &[View]) -> [f64; 3] {
    if views.len() < 2 {
        return [0.0; 3];
    }
    let r0 = views[0].base_flange.rotation;
    let mut m = DMatrix::<f64>::zeros(views.len() - 1, 3);
    for (i, v) in views[1..].iter().enumerate() {
        let w = (r0.inverse() * v.base_flange.rotation).scaled_axis();
        m.set_row(i, &w.transpose());
    }
    let sv = m.singular_values();
    let scale = 1.0 / ((views.len() - 1) as f64).sqrt();
    let mut s = [0.0; 3];
    for (i, v) in sv.iter().take(3).enumerate() {
        s[i] = (v * scale).to_degrees();
    }
    s.sort_by(|a, b| b.total_cmp(a));
    s
}

/// Solve and judge: closed form, refinement, uncertainties; refused as [`Acceptance`] says.
pub fn solve(views: &[View], k: &Intrinsics, acc: &Acceptance) -> Result<Solution, SolveError> {
    let usable: Vec<View> =
        views.iter().filter(|v| v.corners.len() >= acc.min_corners_per_view).cloned().collect();
    if usable.len() < acc.min_views.max(3) {
        return Err(SolveError::TooFewViews(format!(
            "the board was seen (at least {} corners) in {} views; at least {} are needed: \
             take more views",
            acc.min_corners_per_view,
            usable.len(),
            acc.min_views.max(3)
        )));
    }
    let spread = rotation_spread_deg(&usable);
    if spread[1] < acc.min_rotation_spread_deg {
        return Err(SolveError::PoorConditioning(format!(
            "the views turn the camera about one axis only (rotation spread {:.1} / {:.1} / {:.1} \
             deg, the second must be at least {:.1}): add views turned about other axes \
             (more rotation)",
            spread[0], spread[1], spread[2], acc.min_rotation_spread_deg
        )));
    }
    let mut a = Vec::new();
    let mut b = Vec::new();
    for v in &usable {
        let Some(p) = planar_pose(&v.corners, k) else { continue };
        a.push(v.base_flange);
        b.push(p.inverse());
    }
    let (x0, z0) = shah(&a, &b).ok_or_else(|| {
        SolveError::PoorConditioning(
            "the closed form has no unique solution: take more views, with more rotation".into(),
        )
    })?;
    let sol = refine(&usable, k, x0, z0).ok_or_else(|| {
        SolveError::PoorConditioning(
            "the refinement is singular (board behind the camera or views too alike): take more \
             views, with more rotation"
                .into(),
        )
    })?;
    if sol.rms_px > acc.max_rms_px {
        return Err(SolveError::PoorResiduals(format!(
            "reprojection error {:.3} px RMS exceeds {:.3} px: the corners are noisy (focus, \
             motion blur, lighting, a board that is not flat or was moved during the views); fix \
             that and take the views again",
            sol.rms_px, acc.max_rms_px
        )));
    }
    if let Some((i, r)) =
        sol.view_rms_px.iter().enumerate().find(|(_, r)| **r > acc.max_view_rms_px)
    {
        return Err(SolveError::PoorResiduals(format!(
            "view {} has {:.3} px RMS reprojection error (limit {:.3}): it disagrees with the \
             others (a moved board, a blurred frame); take the views again",
            i + 1,
            r,
            acc.max_view_rms_px
        )));
    }
    let worst = [sol.camera_sigma, sol.board_sigma];
    let mm = worst.iter().map(|s| s.mm).fold(0.0, f64::max);
    let deg = worst.iter().map(|s| s.deg).fold(0.0, f64::max);
    if mm > acc.max_sigma_mm || deg > acc.max_sigma_deg {
        return Err(SolveError::PoorConditioning(format!(
            "the solution is too uncertain: camera mount {:.3} mm / {:.4} deg, target {:.3} mm / \
             {:.4} deg (limits {:.3} mm, {:.4} deg, one sigma): take more views, with more \
             rotation",
            sol.camera_sigma.mm,
            sol.camera_sigma.deg,
            sol.board_sigma.mm,
            sol.board_sigma.deg,
            acc.max_sigma_mm,
            acc.max_sigma_deg
        )));
    }
    Ok(sol)
}

/// Levenberg-Marquardt on all reprojection errors from `(x0, z0)`, with the covariance of the
/// result. `None` when a corner falls behind the camera or the normal equations are singular.
pub fn refine(views: &[View], k: &Intrinsics, x0: Pose, z0: Pose) -> Option<Solution> {
    let m: usize = views.iter().map(|v| res_len(&v.corners)).sum();
    let (mut x, mut z) = (x0, z0);
    let f = |x: &Pose, z: &Pose, d: &[f64]| {
        all_residuals(views, k, &(x * increment(&d[0..6])), &(z * increment(&d[6..12])))
    };
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut cost = DVector::from_vec(f(&x, &z, &[0.0; 12])?).norm_squared();
    for it in 0..100 {
        iterations = it + 1;
        let (j, r) = numeric_jacobian::<12>(&|d| f(&x, &z, d), &[0.0; 12], m)?;
        let jtj = j.transpose() * &j;
        let g = j.transpose() * &r;
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = jtj.clone();
            for i in 0..12 {
                damped[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(ch) = damped.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let step = ch.solve(&(-&g));
            let (xn, zn) =
                (x * increment(&step.as_slice()[0..6]), z * increment(&step.as_slice()[6..12]));
            if let Some(rn) = all_residuals(views, k, &xn, &zn) {
                let cn = DVector::from_vec(rn).norm_squared();
                if cn <= cost {
                    let rel = (cost - cn) / cost.max(1e-300);
                    x = xn;
                    z = zn;
                    cost = cn;
                    lambda = (lambda / 10.0).max(1e-12);
                    improved = rel > 1e-14 && step.norm() > 1e-13;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let (j, r) = numeric_jacobian::<12>(&|d| f(&x, &z, d), &[0.0; 12], m)?;
    let jtj: SMatrix<f64, 12, 12> = SMatrix::from_iterator((j.transpose() * &j).iter().copied());
    let dof = (m as f64 - 12.0).max(1.0);
    let s2 = r.norm_squared() / dof;
    let cov = jtj.try_inverse()? * s2;
    // Per-view RMS.
    let mut view_rms_px = Vec::with_capacity(views.len());
    let mut at = 0;
    for v in views {
        let n = res_len(&v.corners);
        let ss: f64 = r.rows(at, n).norm_squared();
        view_rms_px.push((ss / (n as f64 / 2.0)).sqrt());
        at += n;
    }
    let rms_px = (r.norm_squared() / (m as f64 / 2.0)).sqrt();
    let camera_sigma = pose_sigma(&cov.fixed_view::<6, 6>(0, 0).into_owned());
    let board_sigma = pose_sigma(&cov.fixed_view::<6, 6>(6, 6).into_owned());
    Some(Solution {
        camera_mount: x,
        board_in_base: z,
        shah_camera_mount: x0,
        shah_board_in_base: z0,
        rms_px,
        view_rms_px,
        camera_sigma,
        board_sigma,
        covariance: cov,
        iterations,
        corners: m / 2,
    })
}

/// Sigma of a pose whose local increment (translation in its own axes, rotation vector) has
/// covariance `c` (translation is norm-preserving under the pose's rotation).
fn pose_sigma(c: &SMatrix<f64, 6, 6>) -> Sigma {
    let t = c[(0, 0)] + c[(1, 1)] + c[(2, 2)];
    let r = c[(3, 3)] + c[(4, 4)] + c[(5, 5)];
    Sigma { mm: t.max(0.0).sqrt() * 1e3, deg: r.max(0.0).sqrt().to_degrees() }
}

/// Sigma of `z * p` (e.g. the target = board pose times board -> target) given the covariance of
/// `z`'s local increment: the board offset's lever arm turns rotation uncertainty into
/// translation uncertainty.
pub fn composed_sigma(c: &SMatrix<f64, 6, 6>, z: &Pose, p: &Pose) -> Sigma {
    let t0 = z * p;
    let mut j = SMatrix::<f64, 6, 6>::zeros();
    let h = 1e-7;
    for i in 0..6 {
        let mut d = [0.0; 6];
        d[i] = h;
        let t = z * increment(&d) * p;
        let dt = (t.translation.vector - t0.translation.vector) / h;
        let dr = (t0.rotation.inverse() * t.rotation).scaled_axis() / h;
        j.fixed_view_mut::<3, 1>(0, i).copy_from(&dt);
        j.fixed_view_mut::<3, 1>(3, i).copy_from(&dr);
    }
    let out = j * c * j.transpose();
    pose_sigma(&out)
}

/// Difference between two poses: translation (metres) and rotation angle (degrees).
pub fn pose_difference(a: &Pose, b: &Pose) -> (f64, f64) {
    let dt = (a.translation.vector - b.translation.vector).norm();
    let dr = a.rotation.angle_to(&b.rotation).to_degrees();
    (dt, dr)
}
