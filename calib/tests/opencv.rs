//! The solver against OpenCV's `calibrateRobotWorldHandEye` (Shah's method, the
//! opencv-python-headless wheel in `.venv` as a test peer) on the same observations.

use hitl_calib::board::Board;
use hitl_calib::solve::{self, Acceptance, View};
use hitl_calib::views::{self, ViewPlan};
use hitl_calib::Corner;
use hitl_hal::Intrinsics;
use hitl_trajectories::kinematics::flange_pose;
use hitl_trajectories::lab::{BoardPlacement, LabConfig};
use nalgebra::{Isometry3, Matrix3, Matrix4, Translation3, UnitQuaternion, Vector3};
use std::process::Command;

fn k() -> Intrinsics {
    Intrinsics {
        width: 640,
        height: 400,
        fx: 320.0,
        fy: 320.0,
        cx: 319.5,
        cy: 199.5,
        distortion: Default::default(),
    }
}

fn to_json(p: &Isometry3<f64>) -> serde_json::Value {
    let m = p.to_homogeneous();
    serde_json::json!((0..4)
        .map(|r| (0..4).map(|c| m[(r, c)]).collect::<Vec<_>>())
        .collect::<Vec<_>>())
}

fn from_json(v: &serde_json::Value) -> Isometry3<f64> {
    let mut m = Matrix4::zeros();
    for r in 0..4 {
        for c in 0..4 {
            m[(r, c)] = v[r][c].as_f64().expect("number");
        }
    }
    let rot: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    Isometry3::from_parts(
        Translation3::from(Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)])),
        UnitQuaternion::from_matrix(&rot),
    )
}

#[test]
fn agrees_with_opencv_calibrate_robot_world_hand_eye() {
    let python = env!("HITL_VENV_PYTHON");
    assert!(std::path::Path::new(python).exists(), "no venv at {python}: run make setup");
    let lab = LabConfig { board: Some(BoardPlacement::default()), ..LabConfig::default() };
    let board = Board::new(&BoardPlacement::default()).expect("board");
    let d = |t: [f64; 3], r: [f64; 3]| {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_euler_angles(
                r[0].to_radians(),
                r[1].to_radians(),
                r[2].to_radians(),
            ),
        )
    };
    let true_x = lab.camera_mount() * d([0.004, -0.003, 0.002], [1.0, 2.0, -1.5]);
    let true_z = views::board_in_base(&lab, &board) * d([-0.012, 0.02, 0.01], [3.0, -2.0, 2.5]);
    let (planned, _) = views::plan_views(&lab, &board, &k(), &ViewPlan::default());
    let mut seed = 11u64;
    let mut noise = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.6 // uniform, +-0.3 px
    };
    let mut obs = Vec::new();
    let mut json_views = Vec::new();
    for v in &planned {
        let a = flange_pose(&v.q);
        let cam_board = true_x.inverse() * a.inverse() * true_z;
        let mut corners = Vec::new();
        for t in 0..board.tag_count() {
            for p in board.corners(t) {
                let c = cam_board * p;
                let px =
                    (k().fx * c.x / c.z + k().cx + noise(), k().fy * c.y / c.z + k().cy + noise());
                corners.push(Corner { board: p, pixel: px });
            }
        }
        let pose = solve::planar_pose(&corners, &k()).expect("planar pose");
        json_views.push(serde_json::json!({
            "base_flange": to_json(&a),
            "board_camera": to_json(&pose.inverse()),
            "board_points": corners.iter().map(|c| [c.board.x, c.board.y, c.board.z]).collect::<Vec<_>>(),
            "pixels": corners.iter().map(|c| [c.pixel.0, c.pixel.1]).collect::<Vec<_>>(),
        }));
        obs.push(View { base_flange: a, corners });
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("views.json");
    let kk = k();
    let doc = serde_json::json!({"k": {"fx": kk.fx, "fy": kk.fy, "cx": kk.cx, "cy": kk.cy}, "views": json_views});
    std::fs::write(&input, doc.to_string()).expect("write");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/opencv_rwhe.py");
    let out = Command::new(python).arg(script).arg(&input).output().expect("python runs");
    assert!(out.status.success(), "peer failed: {}", String::from_utf8_lossy(&out.stderr));
    let cv: serde_json::Value = serde_json::from_slice(&out.stdout).expect("peer JSON");

    let ours = solve::solve(&obs, &k(), &Acceptance::default()).expect("solved");
    // 1. The same closed form on the same per-view poses: the same answer.
    let (cx, cz) = (
        from_json(&cv["same_poses"]["camera_mount"]),
        from_json(&cv["same_poses"]["board_in_base"]),
    );
    for (name, a, b) in
        [("camera mount", ours.shah_camera_mount, cx), ("board", ours.shah_board_in_base, cz)]
    {
        let (dt, dr) = solve::pose_difference(&a, &b);
        assert!(
            dt < 1e-6 && dr < 1e-5,
            "Shah {name}: hitl and OpenCV {} differ by {dt} m, {dr} deg",
            cv["opencv"]
        );
    }
    // 2. OpenCV end to end (its own PnP, then Shah) and hitl's refined solution both land near
    // the truth; the refinement on reprojection error is at least as close as OpenCV's.
    let (ox, oz) =
        (from_json(&cv["own_pnp"]["camera_mount"]), from_json(&cv["own_pnp"]["board_in_base"]));
    for (name, ours, theirs, truth) in
        [("camera mount", ours.camera_mount, ox, true_x), ("board", ours.board_in_base, oz, true_z)]
    {
        let (dt_o, dr_o) = solve::pose_difference(&ours, &truth);
        let (dt_c, dr_c) = solve::pose_difference(&theirs, &truth);
        eprintln!(
            "{name}: hitl {:.3} mm {:.4} deg, OpenCV {:.3} mm {:.4} deg",
            dt_o * 1e3,
            dr_o,
            dt_c * 1e3,
            dr_c
        );
        assert!(dt_c < 3e-3 && dr_c < 0.3, "OpenCV {name} off the truth: {dt_c} m, {dr_c} deg");
        assert!(dt_o < 1e-3 && dr_o < 0.1, "hitl {name} off the truth: {dt_o} m, {dr_o} deg");
        assert!(dt_o <= dt_c + 2e-4 && dr_o <= dr_c + 0.01, "hitl {name} worse than OpenCV");
    }
}
