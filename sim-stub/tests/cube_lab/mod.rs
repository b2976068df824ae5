//! The camera tests' scene: the default lab with a cube of side [`SIDE`] as the target, and a
//! camera [`HEIGHT`] above the cube's centre looking straight down.
#![allow(dead_code)] // each test binary uses its own subset

use hitl_sim_stub::mjcf::TargetModel;
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

pub const SIDE: f64 = 0.08;
pub const HEIGHT: f64 = 0.3;

/// A cube of side [`SIDE`] (a mesh of unit half-size, scaled by its greatest dimension).
pub fn cube() -> TargetModel {
    let v: Vec<[f32; 3]> = (0..8)
        .map(|i| {
            [
                (i & 1) as f32 * 2.0 - 1.0,
                ((i >> 1) & 1) as f32 * 2.0 - 1.0,
                ((i >> 2) & 1) as f32 * 2.0 - 1.0,
            ]
        })
        .collect();
    let f = vec![
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    TargetModel { mesh: Some((v, f)), greatest_dimension_m: SIDE, parts: Vec::new() }
}

/// The default lab's model with the cube, the camera pose [`HEIGHT`] above the cube's centre
/// looking straight down (OpenCV axes: x along lab x, y along lab -y), and that centre.
pub fn cube_lab() -> (LabModel, Isometry3<f64>, Point3<f64>) {
    let lab = LabConfig::default();
    let model = LabModel::generated(&lab, &cube()).expect("cube lab");
    let centre = lab.base_in_lab() * lab.target_position_base();
    let camera = Isometry3::from_parts(
        Translation3::from(centre.coords + Vector3::z() * HEIGHT),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    );
    (model, camera, centre)
}
