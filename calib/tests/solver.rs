//! The solver on synthetic views (exact and noisy corners), its refusals, the board drawing and
//! detection of a drawn board through the AprilTag C library.

use hitl_calib::board::Board;
use hitl_calib::solve::{self, Acceptance, SolveError, View};
use hitl_calib::views::{self, ViewPlan};
use hitl_calib::Corner;
use hitl_hal::Intrinsics;
use hitl_trajectories::kinematics::flange_pose;
use hitl_trajectories::lab::{BoardPlacement, LabConfig};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

fn intrinsics() -> Intrinsics {
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

/// A small deterministic normal generator (LCG + Box-Muller).
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
}

/// Views planned in `lab`, observed through `true_x` and `true_z`, with `sigma_px` noise.
fn observe(
    lab: &LabConfig,
    board: &Board,
    true_x: &Isometry3<f64>,
    true_z: &Isometry3<f64>,
    sigma_px: f64,
) -> Vec<View> {
    observe_through(&intrinsics(), lab, board, true_x, true_z, sigma_px)
}

/// [`observe`] by a camera with intrinsics `k` (its lens included).
fn observe_through(
    k: &Intrinsics,
    lab: &LabConfig,
    board: &Board,
    true_x: &Isometry3<f64>,
    true_z: &Isometry3<f64>,
    sigma_px: f64,
) -> Vec<View> {
    let k = *k;
    let (planned, _) = views::plan_views(lab, board, &k, &ViewPlan::default());
    let mut noise = Noise(7);
    planned
        .iter()
        .map(|v| {
            let a = flange_pose(&v.q);
            let cam_board = true_x.inverse() * a.inverse() * true_z;
            let mut corners = Vec::new();
            for t in 0..board.tag_count() {
                for p in board.corners(t) {
                    let c = cam_board * p;
                    let (u, w) = k.project(c.x, c.y, c.z);
                    let u = u + sigma_px * noise.normal();
                    let w = w + sigma_px * noise.normal();
                    corners.push(Corner { board: p, pixel: (u, w) });
                }
            }
            View { base_flange: a, corners }
        })
        .collect()
}

fn perturbed(p: &Isometry3<f64>, t_mm: [f64; 3], rpy_deg: [f64; 3]) -> Isometry3<f64> {
    let d = Isometry3::from_parts(
        Translation3::new(t_mm[0] * 1e-3, t_mm[1] * 1e-3, t_mm[2] * 1e-3),
        UnitQuaternion::from_euler_angles(
            rpy_deg[0].to_radians(),
            rpy_deg[1].to_radians(),
            rpy_deg[2].to_radians(),
        ),
    );
    p * d
}

fn setup() -> (LabConfig, Board, Isometry3<f64>, Isometry3<f64>) {
    let lab = LabConfig { board: Some(BoardPlacement::default()), ..LabConfig::default() };
    let board = Board::new(&BoardPlacement::default()).expect("board");
    let x = perturbed(&lab.camera_mount(), [3.0, -2.0, 4.0], [1.5, -1.0, 2.0]);
    let z = perturbed(&views::board_in_base(&lab, &board), [15.0, -12.0, 8.0], [-2.0, 3.0, 1.0]);
    (lab, board, x, z)
}

#[test]
fn the_plan_has_at_least_15_views_each_seeing_the_whole_board() {
    let (lab, board, _, _) = setup();
    let (planned, dropped) = views::plan_views(&lab, &board, &intrinsics(), &ViewPlan::default());
    assert!(planned.len() >= 15, "{} views kept; dropped {dropped:?}", planned.len());
    let traj = views::trajectory(&planned, &lab, &ViewPlan::default());
    assert_eq!(traj.capture_count(), planned.len());
}

#[test]
fn exact_corners_give_the_true_mount_and_board() {
    let (lab, board, x, z) = setup();
    let obs = observe(&lab, &board, &x, &z, 0.0);
    let acc = Acceptance { max_sigma_mm: 1.0, max_sigma_deg: 1.0, ..Acceptance::default() };
    let sol = solve::solve(&obs, &intrinsics(), &acc).expect("solved");
    let (dt, dr) = solve::pose_difference(&sol.camera_mount, &x);
    assert!(dt < 1e-7 && dr < 1e-6, "camera mount off by {dt} m, {dr} deg");
    let (dt, dr) = solve::pose_difference(&sol.board_in_base, &z);
    assert!(dt < 1e-7 && dr < 1e-6, "board off by {dt} m, {dr} deg");
    // Shah's closed form alone is exact on exact data too.
    let (dt, dr) = solve::pose_difference(&sol.shah_camera_mount, &x);
    assert!(dt < 1e-6 && dr < 1e-5, "closed form camera mount off by {dt} m, {dr} deg");
    assert!(sol.rms_px < 1e-5, "{}", sol.rms_px);
}

#[test]
fn corners_seen_through_a_lens_are_solved_through_it() {
    // A Gemini-class lens: at the 640x400 image's corners it moves a corner by several pixels.
    let (lab, board, x, z) = setup();
    let lens = hitl_hal::Distortion::brown_conrady([-0.08, 0.05, 0.0012, -0.0009, -0.01]);
    let k = intrinsics().with_distortion(lens);
    let obs = observe_through(&k, &lab, &board, &x, &z, 0.0);
    let acc = Acceptance { max_sigma_mm: 1.0, max_sigma_deg: 1.0, ..Acceptance::default() };
    let sol = solve::solve(&obs, &k, &acc).expect("solved");
    let (dt, dr) = solve::pose_difference(&sol.camera_mount, &x);
    assert!(dt < 1e-6 && dr < 1e-5, "camera mount off by {dt} m, {dr} deg");
    let (dt, dr) = solve::pose_difference(&sol.board_in_base, &z);
    assert!(dt < 1e-6 && dr < 1e-5, "board off by {dt} m, {dr} deg");
    assert!(sol.rms_px < 1e-4, "{}", sol.rms_px);
    // The same corners solved as a pinhole's are pixels off: the lens matters.
    let acc = Acceptance { max_rms_px: 100.0, max_sigma_mm: 100.0, max_sigma_deg: 100.0, ..acc };
    let pin = solve::solve(&obs, &intrinsics(), &acc).expect("solved as a pinhole");
    assert!(pin.rms_px > 0.2, "a pinhole fits the lens's corners to {} px", pin.rms_px);
}

#[test]
fn noisy_corners_are_recovered_within_their_uncertainty() {
    let (lab, board, x, z) = setup();
    let obs = observe(&lab, &board, &x, &z, 0.3);
    let sol = solve::solve(&obs, &intrinsics(), &Acceptance::default()).expect("solved");
    assert!((sol.rms_px - 0.3 * 2f64.sqrt()).abs() < 0.05, "rms {}", sol.rms_px);
    let (dt, dr) = solve::pose_difference(&sol.camera_mount, &x);
    assert!(dt * 1e3 < 4.0 * sol.camera_sigma.mm + 0.01, "{dt} m vs sigma {:?}", sol.camera_sigma);
    assert!(dr < 4.0 * sol.camera_sigma.deg + 1e-3, "{dr} deg vs sigma {:?}", sol.camera_sigma);
    assert!(dt < 1e-3 && dr < 0.1, "camera mount off by {dt} m, {dr} deg");
    let (dt, dr) = solve::pose_difference(&sol.board_in_base, &z);
    assert!(dt < 1e-3 && dr < 0.1, "board off by {dt} m, {dr} deg");
    assert!(sol.camera_sigma.mm > 0.0 && sol.board_sigma.deg > 0.0);
}

#[test]
fn refusals_name_the_reason_and_the_remedy() {
    let (lab, board, x, z) = setup();
    let k = intrinsics();
    let noisy = observe(&lab, &board, &x, &z, 3.0);
    match solve::solve(&noisy, &k, &Acceptance::default()) {
        Err(SolveError::PoorResiduals(m)) => assert!(m.contains("px RMS"), "{m}"),
        other => panic!("noise not refused: {:?}", other.map(|s| s.rms_px)),
    }
    let obs = observe(&lab, &board, &x, &z, 0.0);
    match solve::solve(&obs[..5], &k, &Acceptance::default()) {
        Err(SolveError::TooFewViews(m)) => assert!(m.contains("more views"), "{m}"),
        other => panic!("5 views not refused: {:?}", other.map(|s| s.rms_px)),
    }
    // Every view with the same flange rotation: no hand-eye rotation information.
    let same: Vec<View> = obs
        .iter()
        .map(|v| View {
            base_flange: Isometry3::from_parts(
                v.base_flange.translation,
                obs[0].base_flange.rotation,
            ),
            corners: v.corners.clone(),
        })
        .collect();
    match solve::solve(&same, &k, &Acceptance::default()) {
        Err(SolveError::PoorConditioning(m)) => assert!(m.contains("more rotation"), "{m}"),
        other => panic!("one rotation not refused: {:?}", other.map(|s| s.rms_px)),
    }
}

#[test]
fn the_drawing_is_true_to_scale() {
    let board = Board::new(&BoardPlacement::default()).expect("board");
    let svg = board.svg();
    // 6 tags of 30 mm, 5 gaps of 9 mm, a 30 mm quiet zone each side: 285 mm.
    assert!(svg.contains("width=\"285.000mm\""), "{}", &svg[..300]);
    assert!(svg.contains("viewBox=\"0 0 285.000 "), "{}", &svg[..300]);
    let file = hitl_calib::board::load_board_file(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/boards/aprilgrid-6x6.toml"
    )))
    .expect("board file");
    let lab_default = BoardPlacement::default();
    assert_eq!(
        (file.rows, file.cols, file.tag_size_m, file.tag_spacing_m, file.first_id),
        (
            lab_default.rows,
            lab_default.cols,
            lab_default.tag_size_m,
            lab_default.tag_spacing_m,
            lab_default.first_id
        )
    );
}

#[test]
fn apriltag_finds_every_tag_of_a_drawn_board_at_its_corners() {
    let board = Board::new(&BoardPlacement::default()).expect("board");
    let ppm = 1600.0; // 6 px per cell
    let border = 40;
    let (w, h, img) = board.render_frontal(ppm, border);
    let d = hitl_calib::detect(&board, w, h, &img).expect("detect");
    assert_eq!(d.tags.len(), 36, "found {:?}", d.tags);
    assert_eq!(d.foreign_tags, 0);
    // Pixel edges are integers in the drawing; in OpenCV's convention (integer pixel centres)
    // board point x lies at border + x * ppm - 0.5.
    let mut worst: f64 = 0.0;
    let mut mean = [[0.0f64; 2]; 4];
    for (i, c) in d.corners.iter().enumerate() {
        let u = border as f64 + c.board.x * ppm - 0.5;
        let v = border as f64 + c.board.y * ppm - 0.5;
        mean[i % 4][0] += (c.pixel.0 - u) / 36.0;
        mean[i % 4][1] += (c.pixel.1 - v) / 36.0;
        worst = worst.max((c.pixel.0 - u).abs()).max((c.pixel.1 - v).abs());
    }
    // Hard (aliased) edges leave each corner up to about half a pixel off, but not on average.
    assert!(worst < 0.75, "corner off by {worst} px");
    for m in mean.iter().flatten() {
        assert!(m.abs() < 0.15, "mean offsets per corner {mean:?}");
    }
}
