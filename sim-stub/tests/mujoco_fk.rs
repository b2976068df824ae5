//! The generated lab model agrees with the project's own kinematics: MuJoCo's body poses equal
//! `kinematics::link_frames` and the camera site equals `kinematics::camera_pose`, at random
//! joint vectors, for the default lab and for a lab with a turned base and a tilted camera mount.

use hitl_sim_stub::camera::Renderer;
use hitl_sim_stub::mjcf::{self, TargetModel, LINK_BODIES};
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::kinematics::{camera_pose, link_frames, DOF};
use hitl_trajectories::lab::LabConfig;
use mujoco_rs::prelude::{MjData, MjtObjBase};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};

fn random_q(rng: &mut Xoshiro256PlusPlus) -> [f64; DOF] {
    std::array::from_fn(|j| {
        let (lo, hi) = LabConfig::default().arm.joint_table.limits()[j];
        let (lo, hi) = (lo.max(-3.5), hi.min(3.5));
        rng.random_range(lo..hi)
    })
}

fn assert_same(a: &Isometry3<f64>, b: &Isometry3<f64>, what: &str) {
    let dt = (a.translation.vector - b.translation.vector).norm();
    let dr = a.rotation.angle_to(&b.rotation);
    assert!(dt < 1e-9 && dr < 1e-9, "{what}: translation off by {dt:e} m, rotation by {dr:e} rad");
}

fn check_lab(lab: &LabConfig, seed: u64) {
    let model = LabModel::generated(lab, &TargetModel::for_lab(lab)).expect("lab compiles");
    let m = model.model.clone();
    let mut data = MjData::new(m.clone());
    let mut renderer = Renderer::new(model.clone()).expect("renderer");
    let base_inv = lab.base_in_lab().inverse();
    let mount = lab.camera_mount();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    for trial in 0..25 {
        let q = if trial == 0 { [0.0; DOF] } else { random_q(&mut rng) };
        {
            let qpos = data.qpos_mut();
            for j in 0..DOF {
                qpos[model.qpos_adr[j]] = q[j];
            }
        }
        data.forward_kinematics();
        let want = link_frames(&q);
        for (i, name) in LINK_BODIES.iter().enumerate() {
            let b = m.name_to_id(MjtObjBase::mjOBJ_BODY, name).expect("link body");
            let p = data.xpos()[b];
            let r = data.xquat()[b];
            let world = Isometry3::from_parts(
                Translation3::new(p[0], p[1], p[2]),
                UnitQuaternion::from_quaternion(Quaternion::new(r[0], r[1], r[2], r[3])),
            );
            assert_same(&(base_inv * world), &want[i + 1], &format!("{name} at {q:?}"));
        }
        renderer.set_joints(&q);
        let cam = base_inv * renderer.camera_in_lab();
        assert_same(&cam, &camera_pose(&q, &mount), &format!("camera site at {q:?}"));
        assert_same(&renderer.base_in_lab(), &lab.base_in_lab(), "base");
        // The MuJoCo camera looks down its -z with y up: the same optical axis and image axes.
        let c = m.name_to_id(MjtObjBase::mjOBJ_CAMERA, mjcf::CAMERA_NAME).expect("camera");
        let x = data.cam_xmat()[c];
        let mj_z = Vector3::new(x[2], x[5], x[8]);
        let mj_y = Vector3::new(x[1], x[4], x[7]);
        let cv = lab.base_in_lab() * camera_pose(&q, &mount);
        assert!((cv.rotation * Vector3::z() + mj_z).norm() < 1e-9, "optical axis");
        assert!((cv.rotation * Vector3::y() + mj_y).norm() < 1e-9, "image y axis");
    }
}

#[test]
fn body_and_camera_poses_match_the_kinematic_chain() {
    check_lab(&LabConfig::default(), 1);
}

#[test]
fn turned_base_and_tilted_mount_still_match() {
    let mut lab = LabConfig::default();
    lab.arm.base_in_lab_m = [1.1, 0.5, 0.02];
    lab.arm.base_yaw_deg = 30.0;
    lab.camera.translation_m = [0.01, -0.02, 0.07];
    lab.camera.rpy_deg = [5.0, -10.0, 90.0];
    check_lab(&lab, 2);
}
