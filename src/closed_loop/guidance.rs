//! Guidance: the filtered deviation from the plan becomes a correction of the camera's position
//! (lab metres, inside the corridor), and that correction, tick by tick, a joint offset of the
//! upcoming setpoints through the xArm7's camera Jacobian (trajectories' kinematics).
//!
//! The law is the simplest that cancels a steady deviation: the wanted correction is minus the
//! filtered position deviation, mapped to the lab (`-scale * R * dr`), clamped to the corridor.
//! With a displaced target that is the target's displacement as the filter sees it: the chaser
//! moves with the target it sees. The orientation of the camera is kept.

use super::corridor::Corridor;
use super::PlanFrame;
use hitl_hal::{Joints, Pose, DOF};
use hitl_trajectories::ik::{camera_jacobian, pose_error};
use hitl_trajectories::kinematics::camera_pose;
use nalgebra::{Matrix6, Vector3};

/// The camera correction guidance wants (lab metres, base frame), and whether the corridor
/// shortened it.
pub fn wanted_correction(
    frame: &PlanFrame,
    deviation_rtn_m: &Vector3<f64>,
    corridor: &Corridor,
) -> (Vector3<f64>, bool) {
    let lab = -frame.scale * (frame.rtn_to_base * deviation_rtn_m);
    corridor.clamp(&lab)
}

/// The joint offset that moves the camera at `q_plan` by `correction` (base frame, lab metres)
/// with its orientation kept: Newton steps on the camera Jacobian (damped least squares) against
/// forward kinematics, from `guess` (a neighbouring tick's offset; zeros will do), to 1e-12 m and
/// rad. `None` when it does not come within 1 um.
pub fn joint_offset(
    q_plan: &Joints,
    correction: &Vector3<f64>,
    mount: &Pose,
    guess: &Joints,
) -> Option<Joints> {
    let start = camera_pose(q_plan, mount);
    let mut goal = start;
    goal.translation.vector += correction;
    let mut q: Joints = std::array::from_fn(|i| q_plan[i] + guess[i]);
    // Converged far below a micrometre: the offsets of neighbouring ticks are differenced into
    // velocity, acceleration and jerk, which a looser solve would fill with noise (1e-7 m of
    // residual is tens of rad/s^3 of jerk at 250 Hz).
    for _ in 0..12 {
        let (cam, j) = camera_jacobian(&q, mount);
        let e = pose_error(&goal, &cam);
        if e.fixed_rows::<3>(0).norm() < 1e-12 && e.fixed_rows::<3>(3).norm() < 1e-12 {
            return Some(std::array::from_fn(|i| q[i] - q_plan[i]));
        }
        let jjt = j * j.transpose() + Matrix6::identity() * 1e-9;
        let dq = j.transpose() * jjt.try_inverse()? * e;
        for i in 0..DOF {
            q[i] += dq[i];
        }
    }
    let e = pose_error(&goal, &camera_pose(&q, mount));
    (e.fixed_rows::<3>(0).norm() < 1e-6 && e.fixed_rows::<3>(3).norm() < 1e-5)
        .then(|| std::array::from_fn(|i| q[i] - q_plan[i]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_trajectories::lab::LabConfig;
    use nalgebra::Matrix3;

    #[test]
    fn a_correction_moves_the_camera_by_it_and_keeps_its_orientation() {
        let lab = LabConfig::default();
        let mount = lab.camera_mount();
        let q = lab.arm.rest_q;
        let c = Vector3::new(0.002, -0.001, 0.0015);
        let dq = joint_offset(&q, &c, &mount, &[0.0; DOF]).expect("converges");
        let moved: Joints = std::array::from_fn(|i| q[i] + dq[i]);
        let (a, b) = (camera_pose(&q, &mount), camera_pose(&moved, &mount));
        assert!((b.translation.vector - a.translation.vector - c).norm() < 1e-6);
        assert!(a.rotation.angle_to(&b.rotation) < 1e-5);
    }

    #[test]
    fn guidance_cancels_the_deviation_inside_the_corridor() {
        let frame = PlanFrame {
            scale: 0.01,
            rtn_to_base: Matrix3::new(0.0, 0.0, -1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 0.0),
            target_base_m: Vector3::new(0.45, 0.0, 0.3),
            time_scale: 500.0,
            mean_motion_rad_s: 1.457e-4,
        };
        let corridor = Corridor::new(0.003).expect("valid");
        // 0.1 m real radial = 1 mm lab; R maps radial to base -z: the correction is +z.
        let (c, clamped) = wanted_correction(&frame, &Vector3::new(0.1, 0.0, 0.0), &corridor);
        assert!(!clamped);
        assert!((c - Vector3::new(0.0, 0.0, 0.001)).norm() < 1e-12, "{c}");
        let (c, clamped) = wanted_correction(&frame, &Vector3::new(0.0, 1.0, 0.0), &corridor);
        assert!(clamped);
        assert!((c - Vector3::new(0.0, 0.003, 0.0)).norm() < 1e-12, "{c}");
    }
}
