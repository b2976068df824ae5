//! The calibration board in the stub's scene: it costs the physics little, and MuJoCo's renderer
//! draws it so that the AprilTag C library decodes every tag at the corners the board's pose predicts.

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
    // The best of three, taken in turn, so that a busy machine slowing one measurement does not
    // read as the board's cost.
    let (mut with, mut without) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..3 {
        with = with.min(step_time_us(&lab));
        without = without.min(step_time_us(&LabConfig::default()));
    }
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

/// The SITL check of docs/calibration.md without the real-time loop: the views `hitl calibrate`
/// plans from the nominal lab, rendered by MuJoCo in the true lab (camera mount 3.7 mm / ~2 deg
/// and target 15 mm / ~3.9 deg off nominal), detected, solved: both recovered within 1 mm and
/// 0.1 deg.
#[test]
fn rendered_views_recover_the_true_mount_and_target() {
    let true_text = include_str!("../../calib/tests/data/true-lab.toml");
    let mut truth = LabConfig::from_toml(true_text).expect("true lab");
    truth.board = Some(BoardPlacement::default());
    let nominal = LabConfig { board: Some(BoardPlacement::default()), ..LabConfig::default() };
    let board = Board::new(&BoardPlacement::default()).expect("board");
    let k = Preset::Orbbec.at(640, 400);
    let (planned, _) = views::plan_views(&nominal, &board, &k, &ViewPlan::default());
    assert!(planned.len() >= 15, "{} views", planned.len());
    let model = LabModel::generated(&truth, &hitl_sim_stub::mjcf::TargetModel::for_lab(&truth))
        .expect("scene");
    let mut gl = GlRenderer::new(model, k.width, k.height).expect("MuJoCo renderer (EGL)");
    let mut seen = Vec::new();
    for v in &planned {
        gl.set_joints(&v.q);
        let a = hitl_trajectories::kinematics::flange_pose(&v.q);
        let camera = truth.base_in_lab() * a * truth.camera_mount();
        let img = gl.render_from(&camera, &k, 1.0, [0.0, 0.0]).expect("render");
        let grey = hitl_calib::detect::rgb_to_grey(&img.color);
        let d =
            hitl_calib::detect(&board, k.width as usize, k.height as usize, &grey).expect("detect");
        // Where the truth projects each corner.
        let cam_board =
            camera.inverse() * truth.base_in_lab() * views::board_in_base(&truth, &board);
        let rms = (d
            .corners
            .iter()
            .map(|c| {
                let p = cam_board * c.board;
                (k.fx * p.x / p.z + k.cx - c.pixel.0).powi(2)
                    + (k.fy * p.y / p.z + k.cy - c.pixel.1).powi(2)
            })
            .sum::<f64>()
            / d.corners.len().max(1) as f64)
            .sqrt();
        assert!(
            rms < 1.0,
            "view {}: corners {rms} px from where the truth puts them",
            seen.len() + 1
        );
        seen.push(hitl_calib::View { base_flange: a, corners: d.corners });
    }
    let sol = hitl_calib::solve(&seen, &k, &hitl_calib::Acceptance::default()).expect("solved");
    let target = sol.board_in_base * BoardPlacement::default().board_in_target().inverse();
    let (dct, dcr) = hitl_calib::solve::pose_difference(&sol.camera_mount, &truth.camera_mount());
    let (dtt, dtr) = hitl_calib::solve::pose_difference(&target, &truth.target_in_base());
    let (nct, ncr) =
        hitl_calib::solve::pose_difference(&nominal.camera_mount(), &truth.camera_mount());
    let (ntt, ntr) =
        hitl_calib::solve::pose_difference(&nominal.target_in_base(), &truth.target_in_base());
    eprintln!(
        "{} views, {:.3} px RMS; camera mount {:.3} mm {:.4} deg from the truth (nominal {:.1} mm \
         {:.2} deg, sigma {:.3} mm {:.4} deg); target {:.3} mm {:.4} deg (nominal {:.1} mm {:.2} \
         deg, board sigma {:.3} mm {:.4} deg)",
        seen.len(),
        sol.rms_px,
        dct * 1e3,
        dcr,
        nct * 1e3,
        ncr,
        sol.camera_sigma.mm,
        sol.camera_sigma.deg,
        dtt * 1e3,
        dtr,
        ntt * 1e3,
        ntr,
        sol.board_sigma.mm,
        sol.board_sigma.deg
    );
    assert!(dct < 1e-3 && dcr < 0.1, "camera mount off by {dct} m, {dcr} deg");
    // The ground truth a run records (the target in the camera, FK times mount, inverse, times
    // target) with the calibrated lab against the true lab, at every view.
    let mut worst = (0.0f64, 0.0f64);
    for v in &planned {
        let a = hitl_trajectories::kinematics::flange_pose(&v.q);
        let cal = (a * sol.camera_mount).inverse() * target;
        let tru = (a * truth.camera_mount()).inverse() * truth.target_in_base();
        let (t, r) = hitl_calib::solve::pose_difference(&cal, &tru);
        worst = (worst.0.max(t), worst.1.max(r));
    }
    eprintln!(
        "recorded ground truth, calibrated vs true lab: at most {:.3} mm, {:.4} deg",
        worst.0 * 1e3,
        worst.1
    );
    assert!(worst.0 < 1e-3 && worst.1 < 0.1, "ground truth off by {worst:?}");
    assert!(dtt < 1e-3 && dtr < 0.1, "target off by {dtt} m, {dtr} deg");
}
