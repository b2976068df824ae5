//! Pose helpers particular to perception. The pose type itself is [`hitl_hal::Pose`]
//! (`camera_T_target` throughout this crate: `p_camera = pose * p_target`).

use hitl_hal::Pose;
use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The pose with rotation matrix `r` and translation `t`, `p -> r p + t`. `r` must be a rotation
/// up to rounding (an SVD's `U V^T`, a rotation of the registration grid): it is converted, not
/// projected.
pub fn from_rt(r: &Matrix3<f64>, t: &Vector3<f64>) -> Pose {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    Pose::from_parts(Translation3::from(*t), q)
}
