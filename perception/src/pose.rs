//! Small rigid-transform helpers on 4x4 matrices (target-in-camera poses).

use nalgebra::{Matrix3, Matrix4, Rotation3, UnitQuaternion, Vector3};

/// A 4x4 rigid transform, `p_camera = T * p_target`.
pub type Pose = Matrix4<f64>;

/// Builds a pose from a rotation and a translation.
pub fn from_rt(r: &Matrix3<f64>, t: &Vector3<f64>) -> Pose {
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(t);
    m
}

/// Rotation block.
pub fn rotation(t: &Pose) -> Matrix3<f64> {
    t.fixed_view::<3, 3>(0, 0).into_owned()
}

/// Translation column.
pub fn translation(t: &Pose) -> Vector3<f64> {
    t.fixed_view::<3, 1>(0, 3).into_owned()
}

/// Inverse of a rigid transform (exact transpose of the rotation, no general inversion).
pub fn inverse(t: &Pose) -> Pose {
    let rt = rotation(t).transpose();
    from_rt(&rt, &(-(rt * translation(t))))
}

/// Pose from a unit quaternion (w, x, y, z) and a translation.
pub fn from_quat_t(q: [f64; 4], t: [f64; 3]) -> Pose {
    let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    from_rt(uq.to_rotation_matrix().matrix(), &Vector3::new(t[0], t[1], t[2]))
}

/// Rotation angle of a rotation matrix in radians, `|log(R)|`, computed robustly near 0 and pi.
pub fn rotation_angle(r: &Matrix3<f64>) -> f64 {
    // Re-orthonormalise so tiny numerical drift cannot push acos out of its domain.
    let rot = Rotation3::from_matrix(r);
    rot.angle()
}

/// True if every element is finite and the rotation block is orthonormal with det +1 (1e-6).
pub fn is_rigid(t: &Pose) -> bool {
    if t.iter().any(|v| !v.is_finite()) {
        return false;
    }
    let r = rotation(t);
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    err < 1e-6 && (r.determinant() - 1.0).abs() < 1e-6 && t.row(3) == Matrix4::identity().row(3)
}

/// Exponential map of a twist (rotation vector `w`, translation `v`) as a pose
/// (rotation by Rodrigues, translation applied directly: adequate for small ICP increments).
pub fn small_motion(w: &Vector3<f64>, v: &Vector3<f64>) -> Pose {
    let r = Rotation3::new(*w);
    from_rt(r.matrix(), v)
}
