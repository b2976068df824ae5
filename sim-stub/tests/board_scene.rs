//! The calibration board in the stub's scene: it costs the physics little, and MuJoCo's renderer
//! draws it so that kornia-apriltag decodes every tag at the corners the board's pose predicts.

use hitl_calib::board::Board;
use hitl_calib::views::{self, ViewPlan};
use hitl_sim_stub::camera::{GlRenderer, Preset};
use hitl_sim_stub::mujoco_plant::{LabModel, MujocoPlant};
use hitl_sim_stub::plant::Plant;
use hitl_trajectories::lab::{BoardPlacement, LabConfig};
use std::time::Instant;

fn step_time_us(lab: &LabConfig) -> f64 {
    let mut plant = MujocoPlant::new(lab, None).expect("plant");
    plant.advance(0.02);
    let t = Instant::now();
    plant.advance(1.0);
    t.elapsed().as_secs_f64() * 1e6 / 500.0
}

#[test]
fn the_board_is_drawn_and_decoded_where_it_is() {
    let lab = LabConfig { board: Some(BoardPlacement::default()), ..LabConfig::default() };
    let (with, without) = (step_time_us(&lab), step_time_us(&LabConfig::default()));
    eprintln!("MuJoCo step: {with:.1} us with the board, {without:.1} us without");
    assert!(with < 4.0 * without + 50.0, "the board slows the physics: {with} vs {without} us");

    let board = Board::new(&BoardPlacement::default()).expect("board");
    let k = Preset::Orbbec.at(640, 400);
    let (planned, _) = views::plan_views(&lab, &board, &k, &ViewPlan::default());
    let view = &planned[0];
    let model =
        LabModel::generated(&lab, &hitl_sim_stub::mjcf::TargetModel::for_lab(&lab)).expect("scene");
    let mut gl = GlRenderer::new(model, k.width, k.height).expect("MuJoCo renderer (EGL)");
    gl.set_joints(&view.q);
    let img = gl
        .render_from(&(lab.base_in_lab() * view.camera_in_base), &k, 1.0, [0.0, 0.0])
        .expect("render");
    let grey = hitl_calib::detect::rgb_to_grey(&img.color);
    let d = hitl_calib::detect(&board, k.width as usize, k.height as usize, &grey).expect("detect");
    assert_eq!(d.tags.len(), 36, "decoded {:?}", d.tags);
    let z = views::board_in_base(&lab, &board);
    let cam_board = view.camera_in_base.inverse() * z;
    let mut worst: f64 = 0.0;
    for c in &d.corners {
        let p = cam_board * c.board;
        let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
        worst = worst.max(((c.pixel.0 - u).powi(2) + (c.pixel.1 - v).powi(2)).sqrt());
    }
    eprintln!("worst corner {worst:.3} px");
    assert!(worst < 1.0, "corner {worst} px from where the board's pose puts it");
}
