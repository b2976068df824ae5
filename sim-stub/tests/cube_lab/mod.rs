//! The camera tests' scene: the default lab with a cube of side [`SIDE`] as the target, and a
//! camera [`HEIGHT`] above the cube's centre looking straight down.
#![allow(dead_code)] // each test binary uses its own subset

use hitl_sim_stub::mjcf::TargetModel;
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

pub const SIDE: f64 = 0.08;
pub const HEIGHT: f64 = 0.3;

/// The 12 outward-facing triangles of a box whose 8 corners are numbered by bits (x: bit 0,
/// y: bit 1, z: bit 2; a set bit is the high side), as [`box_corners`] lists them.
pub const BOX_TRIANGLES: [[u32; 3]; 12] = [
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

/// The 8 corners of the axis-aligned box from `lo` to `hi`, in [`BOX_TRIANGLES`]'s numbering.
pub fn box_corners(lo: [f32; 3], hi: [f32; 3]) -> [[f32; 3]; 8] {
    std::array::from_fn(|i| std::array::from_fn(|a| if i >> a & 1 == 0 { lo[a] } else { hi[a] }))
}

/// A cube of side [`SIDE`] (a mesh of unit half-size, scaled by its greatest dimension).
pub fn cube() -> TargetModel {
    let v = box_corners([-1.0; 3], [1.0; 3]).to_vec();
    TargetModel {
        mesh: Some((v, BOX_TRIANGLES.to_vec())),
        greatest_dimension_m: SIDE,
        parts: Vec::new(),
    }
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
