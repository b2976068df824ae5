//! The one pose type of the workspace: a rigid transform, and the few helpers every crate needs
//! that nalgebra does not already give.
//!
//! A [`Pose`] named `parent_T_child` maps points of the child frame into the parent frame:
//! `p_parent = parent_T_child * p_child`, translations in metres. Composition reads right to
//! left (`base_T_camera = base_T_flange * flange_T_camera`) and `inverse()` swaps the frames.
//! The lab's frames:
//!
//! - `base`: the arm's base (xArm7 base frame, z up);
//! - `flange`: the arm's tool flange (forward kinematics of the joints);
//! - `camera`: the RGB-D camera's optical frame, OpenCV axes (x right, y down, z forward);
//! - `target`: the spacecraft model's body frame;
//! - `board`: the calibration board's frame (its origin at a corner, z out of the board).
//!
//! It is nalgebra's `Isometry3<f64>`: a unit quaternion and a translation, so composing, inverting,
//! mapping points (`transform_point`), the 4x4 matrix (`to_homogeneous`) and the angle between two
//! rotations (`rotation.angle_to`) are nalgebra's. Quaternions cross this workspace's boundaries
//! (recordings, files, peers, models) as `[x, y, z, w]`, the order of nalgebra's `coords` and of
//! Foxglove's messages: [`from_quat_xyzw_t`] and [`quat_xyzw`] are the one place that order is
//! spelt out. Matrices and quaternions from outside (a model's output, a peer's reply, a file)
//! enter through [`from_matrix_checked`] or [`from_quat_xyzw_t`], which refuse what is not a
//! rigid transform instead of passing NaN on.

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3,
};

/// A rigid transform `parent_T_child` (metres); see the module docs for the frames.
pub type Pose = Isometry3<f64>;

/// Tolerance of [`from_matrix_checked`]: largest element of `R^T R - I`, and of `det R - 1`.
pub const RIGID_TOL: f64 = 1e-6;

/// The pose of a homogeneous 4x4 matrix, or `None` when the matrix is not a rigid transform: an
/// element not finite, the rotation block not orthonormal or its determinant not +1 (within
/// [`RIGID_TOL`]), or a last row other than `0 0 0 1` exactly. For the matrices an estimator, a
/// network or a file hands over.
pub fn from_matrix_checked(m: &Matrix4<f64>) -> Option<Pose> {
    if m.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let orthonormal = (r.transpose() * r - Matrix3::identity()).abs().max() < RIGID_TOL;
    let proper = (r.determinant() - 1.0).abs() < RIGID_TOL;
    let last_row = m[(3, 0)] == 0.0 && m[(3, 1)] == 0.0 && m[(3, 2)] == 0.0 && m[(3, 3)] == 1.0;
    if !(orthonormal && proper && last_row) {
        return None;
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Some(Isometry3::from_parts(Translation3::from(t), q))
}

/// Whether `p` is a usable rigid transform: every number finite and the quaternion of unit
/// length (within [`RIGID_TOL`]). A pose built by nalgebra's constructors always is unless a
/// NaN got in (a diverged solver, say).
pub fn is_rigid(p: &Pose) -> bool {
    let finite = p.translation.vector.iter().chain(p.rotation.coords.iter()).all(|v| v.is_finite());
    finite && (p.rotation.coords.norm() - 1.0).abs() < RIGID_TOL
}

/// The pose of a quaternion `[x, y, z, w]` (re-normalised) and a translation (metres), or `None`
/// when a value is not finite or the quaternion's norm is below 1e-6 (no rotation to speak of).
pub fn from_quat_xyzw_t(q: [f64; 4], t: [f64; 3]) -> Option<Pose> {
    let [x, y, z, w] = q;
    let quat = Quaternion::new(w, x, y, z);
    if q.iter().chain(&t).any(|v| !v.is_finite()) || quat.norm() < 1e-6 {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_quaternion(quat),
    ))
}

/// The pose's rotation as a quaternion `[x, y, z, w]`.
pub fn quat_xyzw(p: &Pose) -> [f64; 4] {
    let c = p.rotation.coords; // nalgebra stores x, y, z, w
    [c.x, c.y, c.z, c.w]
}

/// How far apart two poses are: the distance between their origins (metres) and the angle of the
/// rotation that takes one orientation to the other (radians, in [0, pi]).
pub fn difference(a: &Pose, b: &Pose) -> (f64, f64) {
    ((a.translation.vector - b.translation.vector).norm(), a.rotation.angle_to(&b.rotation))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn sample() -> Pose {
        Isometry3::new(Vector3::new(0.1, -0.2, 0.3), Vector3::new(0.2, 0.5, 0.7) * 0.6)
    }

    #[test]
    fn the_matrix_round_trips_and_maps_points_as_the_pose_does() {
        let p = sample();
        let back = from_matrix_checked(&p.to_homogeneous()).expect("rigid");
        let (dt, dr) = difference(&back, &p);
        assert!(dt < 1e-15 && dr < 1e-12, "{dt} {dr}");
        let x = Point3::new(0.4, 0.5, -0.6);
        let m = p.to_homogeneous() * x.to_homogeneous();
        let y = p.transform_point(&x);
        assert!((0..3).all(|i| (m[i] - y[i]).abs() < 1e-15));
    }

    #[test]
    fn non_rigid_or_non_finite_matrices_are_refused() {
        let good = sample().to_homogeneous();
        let mut scaled = good;
        scaled[(0, 0)] *= 1.01;
        let mut reflected = good;
        reflected.fixed_view_mut::<3, 1>(0, 2).neg_mut();
        let mut nan = good;
        nan[(1, 3)] = f64::NAN;
        let mut projective = good;
        projective[(3, 0)] = 1e-3;
        for m in [scaled, reflected, nan, projective, Matrix4::zeros()] {
            assert_eq!(from_matrix_checked(&m), None, "{m}");
        }
        assert!(is_rigid(&sample()));
        let mut diverged = sample();
        diverged.translation.x = f64::NAN;
        assert!(!is_rigid(&diverged));
        let stretched = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::new_unchecked(Quaternion::new(1.1, 0.0, 0.0, 0.0)),
        );
        assert!(!is_rigid(&stretched));
        // Rounding well inside the tolerance is accepted.
        let mut rounded = good;
        rounded[(0, 1)] += 1e-9;
        assert!(from_matrix_checked(&rounded).is_some());
    }

    #[test]
    fn quaternions_are_xyzw_renormalised_and_bad_ones_refused() {
        let h = std::f64::consts::FRAC_PI_4;
        // 90 degrees about z, given at twice unit length.
        let p = from_quat_xyzw_t([0.0, 0.0, 2.0 * h.sin(), 2.0 * h.cos()], [1.0, 2.0, 3.0])
            .expect("a rotation");
        let x = p.transform_point(&Point3::new(1.0, 0.0, 0.0));
        assert!((x - Point3::new(1.0, 3.0, 3.0)).norm() < 1e-12, "{x}");
        let q = quat_xyzw(&p);
        assert!((q[2] - h.sin()).abs() < 1e-15 && (q[3] - h.cos()).abs() < 1e-15, "{q:?}");
        assert_eq!(from_quat_xyzw_t([0.0; 4], [0.0; 3]), None);
        assert_eq!(from_quat_xyzw_t([0.0, 0.0, 0.0, f64::NAN], [0.0; 3]), None);
        assert_eq!(from_quat_xyzw_t([0.0, 0.0, 0.0, 1.0], [f64::INFINITY, 0.0, 0.0]), None);
    }

    #[test]
    fn the_difference_is_metres_and_radians() {
        let a = sample();
        let turn = Isometry3::new(Vector3::new(0.0, 0.3, -0.4), Vector3::new(0.0, 0.0, 0.25));
        let (dt, dr) = difference(&(a * turn), &a);
        assert!((dt - 0.5).abs() < 1e-12 && (dr - 0.25).abs() < 1e-12, "{dt} {dr}");
    }
}
