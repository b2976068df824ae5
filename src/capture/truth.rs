//! Ground truth for a frame: where the target is in the camera frame (OpenCV axes), from forward
//! kinematics of the arm at exposure, the camera mount and the lab's target pose.

use hitl_hal::{Joints, Pose};
use hitl_record::TfMsg;
use hitl_trajectories::kinematics;
use hitl_trajectories::lab::LabConfig;

/// The fixed transforms of the lab that ground truth needs.
#[derive(Debug, Clone, Copy)]
pub struct LabFrames {
    pub flange_camera: Pose,
    pub base_target: Pose,
}

impl LabFrames {
    pub fn new(lab: &LabConfig) -> Self {
        Self { flange_camera: lab.camera_mount(), base_target: lab.target_in_base() }
    }

    /// `camera_T_target` with the arm at `q`.
    pub fn target_in_camera(&self, q: &Joints) -> Pose {
        let camera = kinematics::flange_pose(q) * self.flange_camera;
        camera.inverse() * self.base_target
    }

    /// The `/tf` record with the arm at `q`.
    pub fn tf(&self, t_ns: u64, q: &Joints) -> TfMsg {
        TfMsg {
            t_ns,
            base_flange: kinematics::flange_pose(q),
            flange_camera: self.flange_camera,
            base_target: self.base_target,
        }
    }
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
            assert!((back.translation.vector[i] - t.translation.vector[i]).abs() < 1e-9);
        }
    }
}
