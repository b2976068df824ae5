//! Ground truth for a frame: where the target is in the camera frame (OpenCV axes), from forward
//! kinematics of the arm at exposure, the camera mount and the lab's target pose.

use hitl_hal::Joints;
use hitl_record::{Pose, TfMsg};
use hitl_trajectories::kinematics;
use hitl_trajectories::lab::LabConfig;
use nalgebra::Isometry3;

/// The fixed transforms of the lab that ground truth needs.
#[derive(Debug, Clone, Copy)]
pub struct LabFrames {
    pub flange_camera: Isometry3<f64>,
    pub base_target: Isometry3<f64>,
}

impl LabFrames {
    pub fn new(lab: &LabConfig) -> Self {
        Self { flange_camera: lab.camera_mount(), base_target: lab.target_in_base() }
    }

    /// `camera_T_target` with the arm at `q`.
    pub fn target_in_camera(&self, q: &Joints) -> Isometry3<f64> {
        let camera = kinematics::flange_pose(q) * self.flange_camera;
        camera.inverse() * self.base_target
    }

    /// The `/tf` record with the arm at `q`.
    pub fn tf(&self, t_ns: u64, q: &Joints) -> TfMsg {
        TfMsg {
            t_ns,
            base_flange: pose(&kinematics::flange_pose(q)),
            flange_camera: pose(&self.flange_camera),
            base_target: pose(&self.base_target),
        }
    }
}

/// A recorder pose from an isometry.
pub fn pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    let t = iso.translation.vector;
    Pose { translation: [t.x, t.y, t.z], rotation: [q.i, q.j, q.k, q.w] }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn the_target_in_the_camera_frame_is_where_fk_puts_it() {
        let lab = LabConfig::default();
        let frames = LabFrames::new(&lab);
        let q = [-1.0, -0.2, 0.0, 1.0, 0.0, 1.2, 0.0];
        let t = frames.target_in_camera(&q);
        let camera = kinematics::camera_pose(&q, &lab.camera_mount());
        let target_base = lab.target_position_base();
        let expected = camera.inverse() * target_base;
        assert!((Point3::from(t.translation.vector) - expected).norm() < 1e-12);
        let tf = frames.tf(7, &q);
        let back = tf.camera_in_target().inverse();
        for i in 0..3 {
            assert!((back.translation[i] - t.translation.vector[i]).abs() < 1e-9);
        }
    }
}
