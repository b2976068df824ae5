//! `hitl calibrate`: find where the camera sits on the flange and where the target really is.
//!
//! Plans views of the calibration board on the target's mount (hitl_calib::views), plays them
//! as one trajectory through `hitl run`'s session (the same preflight, interlocks, approach and
//! confirmation for a real arm), recording the captures to a temporary MCAP file; detects the
//! board in each colour frame (the AprilTag C library), solves the robot-world-hand-eye problem with the
//! flange poses the recording holds (forward kinematics of the joints at exposure) and writes the
//! lab configuration with the recovered camera mount and target pose and a `[calibration]`
//! provenance block, atomically (a temporary file renamed into place: a refusal leaves nothing).
//! The views' trajectory is handed to the session in memory (never written to a file); the
//! recording lives in a temporary folder removed on exit unless `--record` keeps it;
//! `--from-recording` solves such a recording again without moving anything (other thresholds, a
//! corrected board definition).
//!
//! Refusals, each with its reason and remedy (docs/calibration.md): 3 the solution's residuals or
//! conditioning are poor (noise; views too alike); [`TOO_FEW_VIEWS`] fewer usable views than the
//! minimum (also: a `--from-recording` file, cut short or not, holding fewer captures than a live
//! calibration plans); [`BOARD_OUT_OF_VIEW`] the board was seen, but not whole in enough views;
//! [`NEVER_DETECTED`] no tag of the board in any capture. A plan with fewer than
//! [`MIN_PLANNED_VIEWS`] reachable views is refused before anything moves.

use crate::cli::device_flags::{DeviceFlags, LabFlags, Labs, Refusal, SimCameraFlags};
use crate::exit;
use crate::rt::RtOptions;
use crate::session::{self, ArmTarget, RunRequest, TrajectorySource};
use foxglove::messages as fg;
use hitl_calib::board::{load_board_file, Board};
use hitl_calib::solve::{self, Acceptance, SolveError, View};
use hitl_calib::views::{self, ViewPlan};
use hitl_hal::Intrinsics;
use hitl_perception::{BackendSpec, ReregisterPolicy};
use hitl_record::{reader, topics};
use hitl_trajectories::lab::{BoardPlacement, CalibrationProvenance, LabConfig};
use nalgebra::Isometry3;
use std::io::IsTerminal;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// Exit code: fewer usable views than the minimum (take more views).
pub const TOO_FEW_VIEWS: u8 = 10;
/// Exit code: the board was seen but not whole in enough views (check its placement).
pub const BOARD_OUT_OF_VIEW: u8 = 11;
/// Exit code: no tag of the board was detected in any capture.
pub const NEVER_DETECTED: u8 = 12;
/// Fewest views a plan must keep.
pub const MIN_PLANNED_VIEWS: usize = 15;

#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// Write the calibrated lab configuration here (TOML).
    #[arg(long, value_name = "CALIBRATED.toml")]
    pub out: Option<PathBuf>,
    /// Write the board as an SVG true to scale (width and height in mm) and exit.
    #[arg(long, value_name = "FILE.svg")]
    pub print_board: Option<PathBuf>,
    /// The board definition (a `[board]` TOML file such as calib/boards/aprilgrid-6x6.toml);
    /// default: the lab configuration's `[board]`, else that repository board.
    #[arg(long, value_name = "BOARD.toml")]
    pub board: Option<PathBuf>,
    #[command(flatten)]
    pub devices: DeviceFlags,
    /// The controller's lab (its nominal camera mount and target pose), the stub's hidden true
    /// lab (the truth to recover) and the operator's confirmation.
    #[command(flatten)]
    pub labs: LabFlags,
    #[command(flatten)]
    pub sim_camera: SimCameraFlags,
    /// Views to plan (15-25).
    #[arg(long, default_value_t = 20, value_name = "N")]
    pub views: usize,
    /// Keep the captures: record the calibration run to this MCAP file.
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Move nothing: solve the captures of an earlier calibration run (a file written with
    /// `--record`) again, e.g. with another --max-rms-px or a corrected --board. The planning,
    /// arm and camera options do not apply.
    #[arg(long, value_name = "FILE.mcap", conflicts_with_all = ["arm", "stub_config", "record"])]
    pub from_recording: Option<PathBuf>,
    /// Largest RMS reprojection error accepted, pixels.
    #[arg(long, default_value_t = Acceptance::default().max_rms_px, value_name = "PX")]
    pub max_rms_px: f64,
    /// SCHED_FIFO priority of the loop thread (0: normal scheduler).
    /// 1-99: Linux's SCHED_FIFO range.
    #[arg(long, default_value_t = 80, value_name = "PRIO",
          value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// Print plain progress lines even on a terminal.
    #[arg(long)]
    pub plain: bool,
    /// The views' run on the host's clock (realtime) or on simulated time in lockstep with the
    /// embedded stub (sim: as fast as the machine allows, as `hitl run --clock sim`); sim is
    /// refused with --arm (docs/sim-clock.md).
    #[arg(long, value_enum, default_value_t = session::ClockChoice::Realtime)]
    pub clock: session::ClockChoice,
}

fn refuse<T>(code: u8, m: impl Into<String>) -> Result<T, Refusal> {
    Err(Refusal(code, m.into()))
}

pub fn run(args: CalibrateArgs) -> u8 {
    match calibrate(args) {
        Ok(()) => exit::OK,
        Err(Refusal(code, m)) => {
            crate::errln!("hitl calibrate: {m}");
            code
        }
    }
}

fn board_placement(args: &CalibrateArgs, lab: &LabConfig) -> Result<BoardPlacement, Refusal> {
    match (&args.board, &lab.board) {
        (Some(path), _) => {
            let mut b =
                load_board_file(path).map_err(|e| Refusal(exit::BAD_INPUT, e.to_string()))?;
            if let Some(l) = &lab.board {
                // The lab's placement of the board on the mount, the file's geometry.
                b.position_target_m = l.position_target_m;
                b.rpy_deg = l.rpy_deg;
            }
            Ok(b)
        }
        (None, Some(b)) => Ok(b.clone()),
        (None, None) => Ok(BoardPlacement::default()),
    }
}

/// Write `bytes` to `path` through a temporary file in the same folder, renamed into place.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Refusal> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let fail = |e: std::io::Error| {
        Refusal(exit::BAD_INPUT, format!("cannot write {}: {e}", path.display()))
    };
    std::fs::write(&tmp, bytes).map_err(fail)?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        fail(e)
    })
}

fn calibrate(args: CalibrateArgs) -> Result<(), Refusal> {
    let labs = args.labs.load(args.devices.arm.as_deref())?;
    let lab = labs.controller.clone();
    let placement = board_placement(&args, &lab)?;
    let board = Board::new(&placement).map_err(|e| Refusal(exit::BAD_INPUT, e.to_string()))?;
    if let Some(svg) = &args.print_board {
        write_atomic(svg, board.svg().as_bytes())?;
        let (w, h) = board.extent_m();
        crate::outln!(
            "board: {} ({:.1} x {:.1} mm of tags) written to {}; print at 100 % and measure a tag",
            board.describe(),
            w * 1e3,
            h * 1e3,
            svg.display()
        );
        if args.out.is_none() {
            return Ok(());
        }
    }
    let Some(out) = args.out.clone() else {
        return refuse(
            exit::BAD_INPUT,
            "--out CALIBRATED.toml is required (or --print-board FILE.svg)",
        );
    };
    for (flag, input) in [("--from-recording", &args.from_recording), ("--record", &args.record)] {
        if input.as_deref().is_some_and(|i| same_file(i, &out)) {
            return refuse(
                exit::BAD_INPUT,
                format!(
                    "--out {} is the recording ({flag}): the calibrated lab would replace it; \
                     choose another --out",
                    out.display()
                ),
            );
        }
    }
    let size = args.sim_camera.camera_size.unwrap_or((640, 400));
    let preset = &args.sim_camera.camera_preset;
    let k = hitl_sim_stub::camera::Preset::from_name(preset)
        .ok_or_else(|| {
            Refusal(exit::BAD_INPUT, format!("--camera-preset {preset:?}: nfov, wfov or orbbec"))
        })?
        .at(size.0, size.1);

    // 1-2. The views planned, played and recorded; or the recording of an earlier run.
    let mut _scratch = None;
    let (record, unreadable) = match &args.from_recording {
        Some(path) => {
            crate::outln!(
                "calibration: solving the captures of {} (nothing moves)",
                path.display()
            );
            (path.clone(), exit::BAD_INPUT)
        }
        None => {
            let dir = Scratch::new()?;
            let record = play_views(&args, &labs, &placement, &board, &k, size, dir.path())?;
            _scratch = Some(dir);
            (record, exit::DEVICE)
        }
    };

    // 3. Detect the board in every capture, with the flange pose at its exposure.
    let min_captures = args.from_recording.is_some().then_some(MIN_PLANNED_VIEWS);
    let (views_seen, k_rec) = read_views(&record, &board, unreadable, min_captures)?;
    let k = k_rec.unwrap_or(k);
    let acc = Acceptance { max_rms_px: args.max_rms_px, ..Acceptance::default() };
    judge_detections(&views_seen, &board, &acc)?;

    // 4. Solve and judge.
    let sol = solve::solve(&views_seen, &k, &acc).map_err(|e| match e {
        SolveError::TooFewViews(m) => Refusal(TOO_FEW_VIEWS, m),
        SolveError::PoorConditioning(m) | SolveError::PoorResiduals(m) => {
            Refusal(exit::PREFLIGHT_REFUSED, m)
        }
    })?;
    let board_in_target = placement.board_in_target();
    let target_in_base = sol.board_in_base * board_in_target.inverse();
    let cov_z = sol.covariance.fixed_view::<6, 6>(6, 6).into_owned();
    let target_sigma =
        solve::composed_sigma(&cov_z, &sol.board_in_base, &board_in_target.inverse());
    report_solution(&sol, &target_in_base, &target_sigma, &lab);

    // 5. The calibrated lab, written atomically.
    let found =
        Found { placement: &placement, board: &board, sol: &sol, target_in_base, target_sigma };
    let text = calibrated_lab(&args, &lab, &found)?;
    write_atomic(&out, text.as_bytes())?;
    crate::outln!("calibrated lab configuration: {}", out.display());
    Ok(())
}

/// Print the solution: per-view and overall reprojection, and how far the camera mount and the
/// target moved from the lab's nominal poses.
fn report_solution(
    sol: &solve::Solution,
    target_in_base: &hitl_hal::Pose,
    target_sigma: &solve::Sigma,
    lab: &LabConfig,
) {
    for (i, r) in sol.view_rms_px.iter().enumerate() {
        crate::outln!("view {:2}: {:.3} px RMS", i + 1, r);
    }
    let (dcam_t, dcam_r) = solve::pose_difference(&sol.camera_mount, &lab.camera_mount());
    let (dtgt_t, dtgt_r) = solve::pose_difference(target_in_base, &lab.target_in_base());
    crate::outln!(
        "reprojection {:.3} px RMS over {} corners in {} views ({} LM iterations)",
        sol.rms_px,
        sol.corners,
        sol.view_rms_px.len(),
        sol.iterations
    );
    crate::outln!(
        "camera mount: +-{:.3} mm, +-{:.4} deg (1 sigma); {:.2} mm, {:.3} deg from nominal",
        sol.camera_sigma.mm,
        sol.camera_sigma.deg,
        dcam_t * 1e3,
        dcam_r
    );
    crate::outln!(
        "target pose:  +-{:.3} mm, +-{:.4} deg (1 sigma); {:.2} mm, {:.3} deg from nominal",
        target_sigma.mm,
        target_sigma.deg,
        dtgt_t * 1e3,
        dtgt_r
    );
}

/// What the solve found, for the calibrated lab.
struct Found<'a> {
    placement: &'a BoardPlacement,
    board: &'a Board,
    sol: &'a solve::Solution,
    target_in_base: hitl_hal::Pose,
    target_sigma: solve::Sigma,
}

/// The calibrated lab's text: `lab` with the solved camera mount and target pose, the board and
/// the calibration's provenance; refused when the result is not a valid lab.
fn calibrated_lab(
    args: &CalibrateArgs,
    lab: &LabConfig,
    found: &Found<'_>,
) -> Result<String, Refusal> {
    let mut calibrated = lab.clone();
    calibrated.board = Some(found.placement.clone());
    let (t, rpy) = parts(&found.sol.camera_mount);
    calibrated.camera.translation_m = t;
    calibrated.camera.rpy_deg = rpy;
    let (t, rpy) = parts(&found.target_in_base);
    calibrated.target.position_base_m = t;
    calibrated.target.rpy_deg = rpy;
    calibrated.calibration = Some(CalibrationProvenance {
        date: utc_now(),
        method: "hitl calibrate: AprilTag (C library) corners, per-view homography pose, Shah's \
                 robot-world-hand-eye closed form, joint Levenberg-Marquardt on reprojection error"
            .into(),
        board: found.board.describe(),
        views: found.sol.view_rms_px.len() as u32,
        rms_px: round(found.sol.rms_px, 4),
        view_rms_px: found.sol.view_rms_px.iter().map(|r| round(*r, 4)).collect(),
        camera_sigma_mm: round(found.sol.camera_sigma.mm, 4),
        camera_sigma_deg: round(found.sol.camera_sigma.deg, 5),
        target_sigma_mm: round(found.target_sigma.mm, 4),
        target_sigma_deg: round(found.target_sigma.deg, 5),
    });
    calibrated.validate().map_err(|e| {
        Refusal(exit::PREFLIGHT_REFUSED, format!("the calibrated lab is not valid: {e}"))
    })?;
    let text = format!(
        "# Written by hitl calibrate on {} from {}.\n{}",
        calibrated.calibration.as_ref().map(|c| c.date.clone()).unwrap_or_default(),
        args.labs.config.as_ref().map_or("the default lab".into(), |p| p.display().to_string()),
        calibrated.to_toml()
    );
    Ok(text)
}

/// The views' trajectory, planned in `lab_with_board`, each view solved and in view; refused
/// before anything moves if too few views are reachable. Its preflight is the run's
/// ([`session::preflight`], in [`play_views`]): one check of the trajectory per run.
fn planned_views(
    args: &CalibrateArgs,
    lab_with_board: &LabConfig,
    board: &Board,
    k: &Intrinsics,
) -> Result<(hitl_trajectories::Trajectory, usize), Refusal> {
    let plan = ViewPlan { count: args.views, ..ViewPlan::default() };
    let (planned, dropped) = views::plan_views(lab_with_board, board, k, &plan);
    for d in &dropped {
        crate::errln!("note: view {} dropped: {}", d.index + 1, d.reason);
    }
    if planned.len() < MIN_PLANNED_VIEWS {
        return refuse(
            TOO_FEW_VIEWS,
            format!(
                "only {} of {} views are reachable with the whole board in the image (at least \
                 {MIN_PLANNED_VIEWS} are needed); nothing moved. Check the board's placement in \
                 [board] and the target pose, or ask for more views (--views)",
                planned.len(),
                args.views
            ),
        );
    }
    Ok((views::trajectory(&planned, lab_with_board, &plan), planned.len()))
}

/// The views' run preflighted in the controller's lab (every rule over its setpoints, the
/// camera's capture rate included); a refusal said as the views' (exit 3, nothing moved).
fn preflight_views(request: RunRequest) -> Result<session::PreflightedRun, Refusal> {
    session::preflight(request).map_err(|e| match e {
        session::RunError::Refused(lines) => Refusal(
            exit::PREFLIGHT_REFUSED,
            format!("preflight refused the views' trajectory; nothing moved:\n{lines}"),
        ),
        e => Refusal(e.exit_code(), e.to_string()),
    })
}

/// Plans the views (refused before anything moves if too few are reachable with the board whole
/// in the image), preflights them as one trajectory and plays it through the run session,
/// recording the captures; returns the recording's path (in `dir` unless `--record`).
fn play_views(
    args: &CalibrateArgs,
    labs: &Labs,
    placement: &BoardPlacement,
    board: &Board,
    k: &Intrinsics,
    size: (u32, u32),
    dir: &Path,
) -> Result<PathBuf, Refusal> {
    if !(MIN_PLANNED_VIEWS..=views::MAX_VIEWS).contains(&args.views) {
        return refuse(
            TOO_FEW_VIEWS,
            format!(
                "--views {}: plan {MIN_PLANNED_VIEWS} to {} views",
                args.views,
                views::MAX_VIEWS
            ),
        );
    }
    let lab = &labs.controller;
    let mut stub_lab = labs.stub.clone();
    // The board is on the mount in the simulated lab too, where its own [board] (or ours) says.
    if let Some(s) = stub_lab.as_mut() {
        s.board.get_or_insert_with(|| placement.clone());
    }
    let mut lab_with_board = lab.clone();
    lab_with_board.board = Some(placement.clone());
    // Without a hidden truth, the stub simulates the controller's lab, board included.
    if args.devices.arm.is_none() && stub_lab.is_none() {
        stub_lab = Some(lab_with_board.clone());
    }

    // 1. The views, each solved and in view; refused before anything moves.
    let (traj, count) = planned_views(args, &lab_with_board, board, k)?;

    // 2. The run that plays them, recording the captures: handed the trajectory in memory,
    // preflighted before the operator confirms a real arm.
    let record = args.record.clone().unwrap_or_else(|| dir.join("calibration.mcap"));
    let target = match &args.devices.arm {
        None => ArmTarget::Stub { faults: Vec::new() },
        Some(host) => ArmTarget::Remote { host: host.clone() },
    };
    let request = RunRequest {
        trajectory: TrajectorySource::InMemory {
            trajectory: Box::new(traj),
            name: "calibration views (planned by hitl calibrate)".into(),
        },
        lab: lab.clone(),
        rate_hz: 250.0,
        speed_scale: 1.0,
        target,
        record: Some(record.clone()),
        record_compression: hitl_record::RecorderConfig::default().compression,
        camera: args.devices.run_camera(),
        light: args.devices.run_light(),
        trigger: args.devices.run_trigger(),
        perception: BackendSpec::None,
        reregister: ReregisterPolicy::default(),
        // The board is found in colour: no target mask is drawn (the simulator's is kept).
        mask: match args.devices.run_camera() {
            crate::devices::CameraSpec::Sim => crate::capture::mask::MaskSource::Sim,
            _ => crate::capture::mask::MaskSource::None,
        },
        mask_margin_px: 0,
        camera_preset: args.sim_camera.camera_preset.clone(),
        camera_size: Some(size),
        target_model: "asymmetric".into(),
        stub_lab,
        depth_model: Default::default(),
        rt: RtOptions::with_priority(args.rt_priority),
        // Back to the rest pose after the views, as every completed run.
        retreat: true,
        stub_start_q: None,
        plain_progress: args.plain || !std::io::stderr().is_terminal(),
        live: None,
        closed_loop: None,
        clock: args.clock,
    };
    let run = preflight_views(request)?;
    crate::outln!(
        "calibration: {count} views of {}, {:.1} s of motion",
        board.describe(),
        run.trajectory().duration()
    );
    if let Some(host) = &args.devices.arm {
        args.labs.confirm_real_arm(host)?;
    }
    match run.play() {
        Ok(r) if r.exit_code == exit::OK => {}
        Ok(r) => {
            return refuse(
                r.exit_code,
                format!("the views' run did not complete:\n{}", r.summary()),
            )
        }
        Err(e) => return refuse(e.exit_code(), e.to_string()),
    }
    Ok(record)
}

/// Refuse captures that cannot be solved: no tag of the board anywhere ([`NEVER_DETECTED`]), or
/// the board whole in too few of them ([`BOARD_OUT_OF_VIEW`]).
fn judge_detections(views_seen: &[View], board: &Board, acc: &Acceptance) -> Result<(), Refusal> {
    let tags_seen: usize = views_seen.iter().map(|v| v.corners.len()).sum();
    let whole = views_seen.iter().filter(|v| v.corners.len() >= acc.min_corners_per_view).count();
    crate::outln!(
        "captures: {}, board seen in {whole} (corners per view: {:?})",
        views_seen.len(),
        views_seen.iter().map(|v| v.corners.len()).collect::<Vec<_>>()
    );
    if tags_seen == 0 {
        return refuse(
            NEVER_DETECTED,
            format!(
                "no tag of the board ({}) was detected in any of the {} captures: check that the \
                 board is mounted and lit, that it is the board named in [board] (family, first \
                 id), and that the camera is focused",
                board.describe(),
                views_seen.len()
            ),
        );
    }
    let detected = views_seen.iter().filter(|v| !v.corners.is_empty()).count();
    if detected < acc.min_views {
        return refuse(
            TOO_FEW_VIEWS,
            format!(
                "the board was detected in only {detected} of {} captures; at least {} views \
                 with the board are needed: take more views",
                views_seen.len(),
                acc.min_views
            ),
        );
    }
    if whole < acc.min_views {
        return refuse(
            BOARD_OUT_OF_VIEW,
            format!(
                "the board was seen whole (at least {} corners) in only {whole} of {} captures: \
                 it is not where [board] and the target pose put it (off by more than the views' \
                 margin); measure its placement again and rerun",
                acc.min_corners_per_view,
                views_seen.len()
            ),
        );
    }

    Ok(())
}

fn round(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    (v * s).round() / s
}

/// Translation (m) and roll, pitch, yaw (deg, z-y-x) as the lab configuration writes them.
fn parts(p: &Isometry3<f64>) -> ([f64; 3], [f64; 3]) {
    let t = p.translation.vector;
    let (r, pi, y) = p.rotation.euler_angles();
    ([t.x, t.y, t.z], [r.to_degrees(), pi.to_degrees(), y.to_degrees()])
}

fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// Whether two paths name the same file (both canonicalised; a path that does not exist yet is
/// no existing file).
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

/// A private temporary folder for the views' trajectory and recording, removed when dropped.
struct Scratch(tempfile::TempDir);

impl Scratch {
    fn new() -> Result<Self, Refusal> {
        tempfile::Builder::new()
            .prefix("hitl-calibrate-")
            .tempdir()
            .map(Scratch)
            .map_err(|e| Refusal(exit::DEVICE, format!("cannot create a temporary folder: {e}")))
    }

    fn path(&self) -> &Path {
        self.0.path()
    }
}

/// The recording's colour captures, each with the flange pose at its exposure (from `/tf`) and
/// the board corners found in it; and the camera's intrinsics as recorded. A recording that was
/// not read to its end (cut short, damaged) is used as far as it is sound, and says so; with
/// `min_captures` (`--from-recording`: the fewest views a live calibration plans), fewer
/// captures than that are refused with [`TOO_FEW_VIEWS`] before any detection.
fn read_views(
    path: &Path,
    board: &Board,
    code: u8,
    min_captures: Option<usize>,
) -> Result<(Vec<View>, Option<Intrinsics>), Refusal> {
    let bad = |m: String| {
        Refusal(code, format!("reading the calibration recording {}: {m}", path.display()))
    };
    let rec = reader::read_recording(path)
        .map_err(|e| Refusal(code, format!("the calibration recording: {e}")))?;
    let end = rec.end.clone();
    let partial = end.as_ref().and_then(|e| e.warning(path));
    if let Some(w) = &partial {
        crate::errln!("hitl calibrate: warning: {w}");
    }
    let mut images: Vec<(u64, fg::RawImage)> = Vec::new();
    let mut k: Option<Intrinsics> = None;
    reader::visit(
        path,
        |m| {
            if m.topic == topics::COLOR {
                if let Ok(img) = reader::decode_image(m.data) {
                    let t = img.timestamp.map(|t| t.total_nanos()).unwrap_or(m.log_time);
                    images.push((t, img));
                }
            } else if m.topic == topics::CALIBRATION && k.is_none() {
                k = reader::decode_intrinsics(m.data, m.log_time).ok().map(|(_, k)| k);
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .map_err(|e| bad(e.to_string()))?;
    images.sort_by_key(|(t, _)| *t);
    if let Some(min) = min_captures.filter(|m| images.len() < *m) {
        let read = match (&partial, &end) {
            (Some(_), Some(e)) => format!(
                "{} was not read to its end ({}; {}): what was read",
                path.display(),
                e.truncated.as_deref().unwrap_or("it stopped early"),
                e.frames_text()
            ),
            _ => path.display().to_string(),
        };
        return refuse(
            TOO_FEW_VIEWS,
            format!(
                "{read} holds {} captures, fewer than the {min} views a calibration solves from \
                 (as many as a live one plans); record the views again (hitl calibrate --record)",
                images.len()
            ),
        );
    }
    let mut out = Vec::new();
    for (t, img) in images {
        let Some(tf) = rec.tf.iter().min_by_key(|m| m.t_ns.abs_diff(t)) else { continue };
        if tf.t_ns.abs_diff(t) > 20_000_000 {
            continue;
        }
        let bpp = match img.encoding.as_str() {
            "rgb8" => 3,
            "mono8" => 1,
            other => return Err(bad(format!("colour encoding {other} is not rgb8 or mono8"))),
        };
        let pixels = reader::packed_rows(&img, bpp).ok_or_else(|| {
            bad(format!(
                "a {}x{} {} image of {} bytes",
                img.width,
                img.height,
                img.encoding,
                img.data.len()
            ))
        })?;
        let grey = if bpp == 3 { hitl_calib::detect::rgb_to_grey(&pixels) } else { pixels };
        let det = hitl_calib::detect(board, img.width as usize, img.height as usize, &grey)
            .map_err(|e| bad(e.to_string()))?;
        out.push(View { base_flange: tf.base_flange, corners: det.corners });
    }
    Ok((out, k))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_calib::Corner;
    use nalgebra::Point3;

    fn view(corners: usize) -> View {
        let c = Corner { board: Point3::origin(), pixel: (0.0, 0.0) };
        View { base_flange: Isometry3::identity(), corners: vec![c; corners] }
    }

    #[test]
    fn captures_without_the_board_are_refused_by_kind() {
        let board = Board::new(&BoardPlacement::default()).expect("board");
        let acc = Acceptance::default();
        let none: Vec<View> = (0..20).map(|_| view(0)).collect();
        let Err(Refusal(code, m)) = judge_detections(&none, &board, &acc) else {
            panic!("accepted")
        };
        assert_eq!(code, NEVER_DETECTED, "{m}");
        assert!(m.contains("no tag"), "{m}");
        // Seen, but whole in only 5 of 20 captures (the rest at the image's edge).
        let partial: Vec<View> = (0..20).map(|i| view(if i < 5 { 144 } else { 8 })).collect();
        let Err(Refusal(code, m)) = judge_detections(&partial, &board, &acc) else {
            panic!("accepted")
        };
        assert_eq!(code, BOARD_OUT_OF_VIEW, "{m}");
        assert!(m.contains("only 5 of 20"), "{m}");
        // Detected in only 6 of 20 (whole in those): too few views, exit 10 as a live run's.
        let few: Vec<View> = (0..20).map(|i| view(if i < 6 { 144 } else { 0 })).collect();
        let Err(Refusal(code, m)) = judge_detections(&few, &board, &acc) else {
            panic!("accepted")
        };
        assert_eq!(code, TOO_FEW_VIEWS, "{m}");
        assert!(m.contains("only 6 of 20"), "{m}");
        let whole: Vec<View> = (0..20).map(|_| view(144)).collect();
        assert!(judge_detections(&whole, &board, &acc).is_ok());
    }

    #[test]
    fn the_output_is_written_whole_or_not_at_all() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("lab.toml");
        write_atomic(&out, b"[camera]\n").expect("written");
        assert_eq!(std::fs::read(&out).expect("read"), b"[camera]\n");
        assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 1, "no temporary left");
        let Err(Refusal(code, _)) = write_atomic(&dir.path().join("missing/lab.toml"), b"x") else {
            panic!("wrote into a missing folder")
        };
        assert_eq!(code, exit::BAD_INPUT);
    }
}
