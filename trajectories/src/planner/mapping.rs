//! From the orbit to the lab: the workspace scale, the RTN-to-base rotation, and the camera pose
//! that looks at the target from the chaser's scaled position.
//!
//! `camera position (base) = target (base) + scale * rtn_to_base * rel_pos_rtn`.
//!
//! The camera (OpenCV axes: x right, y down, z forward) has its optical axis z on the target
//! centre. Its roll follows the **up-vector rule**: image up (-y) is the fixed reference vector `w`
//! projected onto the image plane, where `w` is the unit normal of the relative path's plane in
//! the base frame, signed to point up (w . z_base >= 0); a path without a plane (a fixed point or
//! a straight line) uses the base's +z. `w` is one vector for the whole plan, and a planar path
//! around the target keeps the optical axis perpendicular to it, so the image never flips or rolls
//! through 180 deg. The planner refuses any plan whose optical axis comes within
//! [`MIN_UP_ANGLE_DEG`] of `w` (the only place the rule would be ill-defined).

use hitl_hal::Pose;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The paper's workspace fill fraction alpha.
pub const PAPER_ALPHA: f64 = 0.11;
/// The paper's practical arm reach d_arm, metres.
pub const PAPER_D_ARM_M: f64 = 0.7;

/// The smallest angle allowed between the optical axis and the up reference, degrees.
pub const MIN_UP_ANGLE_DEG: f64 = 20.0;

/// A rotation from roll, pitch, yaw in degrees (R = Rz(yaw) Ry(pitch) Rx(roll)).
pub fn rotation_from_rpy_deg(rpy: &[f64; 3]) -> Matrix3<f64> {
    *Rotation3::from_euler_angles(rpy[0].to_radians(), rpy[1].to_radians(), rpy[2].to_radians())
        .matrix()
}

/// The default RTN-to-base rotation, columns = where R, T and N point in the base frame:
/// R (radial) points down (-z), T (along-track) points to the base's -y, N (orbit normal)
/// points from the target toward the arm (-x). The fly-around's 2:1 ellipse then lies in a plane
/// whose normal leans 45 deg from vertical toward the arm: its long axis (along-track, 2r) runs
/// across in front of the arm, its short axis from low on the arm's side to high beyond the
/// target, so the camera never passes under the target (the tripod) and is on the arm's side of
/// the target on the lower half of the orbit. Of the orientations tried (every 90 deg roll,
/// 45 deg pitch and 90 deg yaw, then yaw and tilt steps of 15 deg around this one) it is the one
/// where the default lab reaches the whole 50 m fly-around.
pub const DEFAULT_RTN_TO_BASE: [[f64; 3]; 3] =
    [[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]];

/// The default RTN-to-base rotation as a matrix (`v_base = M * v_rtn`).
pub fn default_rtn_to_base() -> Matrix3<f64> {
    let r = DEFAULT_RTN_TO_BASE;
    Matrix3::new(r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2])
}

/// The paper's workspace scale s_ws = alpha * d_arm / r_orbit (lab metres per real metre).
pub fn workspace_scale(alpha: f64, d_arm_m: f64, range_m: f64) -> f64 {
    alpha * d_arm_m / range_m
}

/// The up reference `w` (base frame) of a path of relative positions (RTN), by the rule above.
pub fn up_reference(rel_rtn: &[Vector3<f64>], rtn_to_base: &Matrix3<f64>) -> Vector3<f64> {
    let mut normal = Vector3::zeros();
    let mut size2: f64 = 0.0;
    for w in rel_rtn.windows(2) {
        normal += w[0].cross(&w[1]);
    }
    for p in rel_rtn {
        size2 = size2.max(p.norm_squared());
    }
    // A path that sweeps no area (a point, a line, a back-and-forth) has no plane.
    let base_z = Vector3::z();
    if size2 == 0.0 || normal.norm() < 1e-6 * size2 {
        return base_z;
    }
    let w = (rtn_to_base * normal).normalize();
    if w.dot(&base_z) < 0.0 {
        -w
    } else {
        w
    }
}

/// The camera pose at `position` looking at `target`, rolled by the up reference `w`. `None` when
/// the optical axis is within [`MIN_UP_ANGLE_DEG`] of `w` or the camera sits on the target.
pub fn look_at(position: &Point3<f64>, target: &Point3<f64>, w: &Vector3<f64>) -> Option<Pose> {
    let z = (target - position).try_normalize(1e-9)?;
    let along = w.dot(&z);
    if along.abs() > MIN_UP_ANGLE_DEG.to_radians().cos() {
        return None;
    }
    let y = -(w - z * along).normalize();
    let x = y.cross(&z);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Some(Isometry3::from_parts(
        Translation3::from(position.coords),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}
