//! xArm7 forward kinematics, joint limits and the link-capsule model of arm and camera.
//!
//! The chain is the public one (MuJoCo Menagerie's xArm7, see `shared/reference/FACTS.md`): each
//! body is placed in its parent by a translation and a rotation about the parent's x axis, then
//! turns about its own z axis by its joint angle. Frame 0 is the arm base, frames 1-7 are links
//! 1-7; frame 7 is the flange. At the all-zero pose the flange sits at (0.206, 0, 0.1205) m with
//! its z axis pointing down.

use crate::geometry::Capsule;
use hitl_hal::Pose;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::{FRAC_PI_2, PI};

/// The joint count and joint positions are the hal's (one `DOF` in the workspace).
pub use hitl_hal::{Joints, DOF};

/// Each body's offset in its parent: translation (m) and rotation about the parent's x (rad).
pub const CHAIN: [([f64; 3], f64); DOF] = [
    ([0.0, 0.0, 0.267], 0.0),
    ([0.0, 0.0, 0.0], -FRAC_PI_2),
    ([0.0, -0.293, 0.0], FRAC_PI_2),
    ([0.0525, 0.0, 0.0], FRAC_PI_2),
    ([0.0775, -0.3425, 0.0], FRAC_PI_2),
    ([0.0, 0.0, 0.0], FRAC_PI_2),
    ([0.076, 0.097, 0.0], -FRAC_PI_2),
];

// Joint limits: there is no single xArm7 table. The lab's `joint_table::JointTable`
// (`arm.joint_table`) decides offline, and the connected arm's serial number on connect.

/// The xArm7's published maximum joint speed, 180 deg/s.
pub const MAX_JOINT_SPEED: f64 = PI;

/// The fixed offset of body `i` (0-based, link i+1) in its parent, before its joint turns.
pub fn body_offset(i: usize) -> Pose {
    let (p, rx) = CHAIN[i];
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), rx),
    )
}

/// Poses of the base (index 0) and of links 1-7 (indices 1-7) in the base frame.
pub fn link_frames(q: &Joints) -> [Pose; DOF + 1] {
    let mut frames = [Isometry3::identity(); DOF + 1];
    let mut pose = Isometry3::identity();
    for i in 0..DOF {
        pose = pose * body_offset(i) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), q[i]);
        frames[i + 1] = pose;
    }
    frames
}

/// Flange (link 7) pose in the base frame.
pub fn flange_pose(q: &Joints) -> Pose {
    link_frames(q)[DOF]
}

/// Camera pose (OpenCV axes) in the base frame, for a flange-to-camera mount.
pub fn camera_pose(q: &Joints, mount: &Pose) -> Pose {
    flange_pose(q) * mount
}

/// The index of a joint that is outside `limits` (a [`crate::joint_table::JointTable`]'s) shrunk by `margin`, with
/// its value.
pub fn first_joint_beyond_limits(
    q: &Joints,
    limits: &[(f64, f64); DOF],
    margin: f64,
) -> Option<(usize, f64)> {
    q.iter()
        .enumerate()
        .find(|(i, v)| {
            let (lo, hi) = limits[*i];
            !(**v >= lo + margin && **v <= hi - margin)
        })
        .map(|(i, v)| (i, *v))
}

/// Radii of the arm's capsules, metres: the segments between successive joint origins, plus the
/// base column. Generous by a few millimetres on the xArm7's outer shells.
pub const LINK_RADII: [f64; 6] = [0.075, 0.065, 0.060, 0.060, 0.055, 0.050];

/// Names of the capsules [`arm_capsules`] returns, in order.
pub const CAPSULE_NAMES: [&str; 8] =
    ["base", "upper-arm", "elbow", "forearm", "wrist", "hand", "flange", "camera"];

/// Where the camera body sits in the camera frame (OpenCV axes: z forward): a capsule from
/// `back_m` behind the optical centre to the optical centre, across the body's width.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraBody {
    pub half_width_m: f64,
    pub depth_m: f64,
    pub radius_m: f64,
}

impl Default for CameraBody {
    /// An Orbbec Gemini-class body: ~90 mm wide, ~30 mm deep.
    fn default() -> Self {
        Self { half_width_m: 0.045, depth_m: 0.03, radius_m: 0.02 }
    }
}

/// The capsule model of the arm at `q`, in the base frame: six link capsules, the flange and the
/// camera body. Index order is [`CAPSULE_NAMES`].
pub fn arm_capsules(q: &Joints, mount: &Pose, camera: &CameraBody) -> [Capsule; 8] {
    let f = link_frames(q);
    let o = |i: usize| Point3::from(f[i].translation.vector);
    let flange = f[DOF];
    let cam = flange * mount;
    let zero = Point3::origin();
    [
        Capsule::new(Point3::new(0.0, 0.0, 0.0), o(1), LINK_RADII[0]),
        Capsule::new(o(2), o(3), LINK_RADII[1]),
        Capsule::new(o(3), o(4), LINK_RADII[2]),
        Capsule::new(o(4), o(5), LINK_RADII[3]),
        Capsule::new(o(5), o(6), LINK_RADII[4]),
        Capsule::new(o(6), o(7), LINK_RADII[5]),
        // The flange disc and the mount bracket: from the flange face along its z.
        Capsule::new(flange * zero, flange * Point3::new(0.0, 0.0, 0.02), 0.04),
        Capsule::new(
            cam * Point3::new(-camera.half_width_m, 0.0, -camera.depth_m),
            cam * Point3::new(camera.half_width_m, 0.0, -camera.depth_m),
            camera.radius_m,
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_pose_puts_flange_at_reference_pointing_down() {
        let f = flange_pose(&[0.0; DOF]);
        let t = f.translation.vector;
        assert!((t - Vector3::new(0.206, 0.0, 0.1205)).norm() < 1e-9, "{t}");
        let z = f.rotation * Vector3::z();
        assert!((z - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-9, "{z}");
    }

    #[test]
    fn joint1_turns_the_flange_about_base_z() {
        let q = [FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let t = flange_pose(&q).translation.vector;
        assert!((t - Vector3::new(0.0, 0.206, 0.1205)).norm() < 1e-9, "{t}");
    }

    #[test]
    fn shoulder_pitch_moves_the_elbow_in_the_xz_plane() {
        // Joint 2 at +90 deg tilts the upper arm forward: link 3's origin goes from (0,0,0.56)
        // to (0.293, 0, 0.267).
        let q = [0.0, FRAC_PI_2, 0.0, 0.0, 0.0, 0.0, 0.0];
        let t = link_frames(&q)[3].translation.vector;
        assert!((t - Vector3::new(0.293, 0.0, 0.267)).norm() < 1e-9, "{t}");
    }

    #[test]
    fn limits_with_margin() {
        use crate::joint_table::JointTable;
        let (current, legacy) =
            (JointTable::Xarm7Current.limits(), JointTable::Xarm7Legacy.limits());
        let mut q = [0.0; DOF];
        assert_eq!(first_joint_beyond_limits(&q, &current, 0.05), None);
        q[3] = -0.18;
        assert_eq!(first_joint_beyond_limits(&q, &legacy, 0.05), Some((3, -0.18)));
        // J4 at -0.10 rad: inside the first arms' table, outside the current one.
        q[3] = -0.10;
        assert_eq!(first_joint_beyond_limits(&q, &legacy, 0.05), None);
        assert_eq!(first_joint_beyond_limits(&q, &current, 0.0), None);
        assert_eq!(first_joint_beyond_limits(&q, &current, 0.05), Some((3, -0.10)));
        q[3] = 0.5;
        q[1] = f64::NAN;
        assert_eq!(first_joint_beyond_limits(&q, &current, 0.0).map(|x| x.0), Some(1));
    }
}
