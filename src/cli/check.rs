//! `hitl check`: the preflight on its own. Loads and validates the NPZ, builds the setpoint table
//! at the playback rate and speed scale (with the lead-in and lead-out of a file that starts or
//! ends moving), runs every preflight rule at every tick, and prints a short report (or one JSON
//! object). A file refused only for velocity, acceleration, jerk or step gets the largest
//! `--speed-scale` that passes, confirmed by a second preflight. Then the moves between rests a
//! run makes around it: the approach from the lab's rest pose (`[arm] rest_q`, or `--from Q`) to
//! the first setpoint and the retreat from the last back to rest, each planned around the lab's
//! obstacles and checked tick by tick (length, duration, nearest obstacle); a move with no safe
//! path refuses the file. Exit 0 safe, 3 valid but unsafe, 2 bad file, flags or config. `hitl run`
//! applies the same rules before anything moves.

use crate::control::motion::{add_ramps, MotionError};
use crate::control::planned_move::{plan_safe_move, PlannedMove};
use crate::devices::CameraSpec;
use crate::exit;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::npz::{self, Loaded};
use hitl_trajectories::preflight::{self, PreflightReport};
use hitl_trajectories::timing::{SetpointTable, DEFAULT_RATE_HZ, XARM_MAX_SERVO_RATE_HZ};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Preflight a trajectory without moving anything.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// The trajectory: an NPZ file in the schema of docs/npz-schema.md (`qpos` (N,7) radians and
    /// `t` (N,) seconds, plus optional capture, light and planner channels).
    #[arg(value_name = "TRAJ.npz")]
    pub traj: PathBuf,
    /// Lab configuration (TOML: enclosure, arm base, keep-outs, camera mount, margins, limits).
    /// Without it, the built-in DreamSat-Bench lab (every default is documented in the config).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Control rate to check at, Hz (50-1000). Per-tick step sizes depend on it: check at the
    /// rate you will run at.
    #[arg(long, value_name = "HZ", default_value_t = DEFAULT_RATE_HZ)]
    pub rate: f64,
    /// Speed scale in (0, 1]: stretches time as `hitl run --speed-scale` does (0.5 plays at half
    /// speed), lowering velocity, acceleration, jerk and step sizes.
    #[arg(long, value_name = "S", default_value_t = 1.0)]
    pub speed_scale: f64,
    /// Waypoints per second of a file without `t` (a fixed sample rate): waypoint i is at i / HZ
    /// seconds. Refused for a file that has `t`.
    #[arg(long, value_name = "HZ")]
    pub waypoint_rate: Option<f64>,
    /// Check the captures against this camera too (as `hitl run --camera`): an Orbbec camera
    /// follows captures at most at half its stream's frame rate (15 Hz at 30 fps), so faster
    /// captures are refused with a --speed-scale remedy. Without it, no camera rule applies.
    #[arg(long, value_name = "sim|orbbec[:hardware|:software]|none")]
    pub camera: Option<CameraSpec>,
    /// Plan and check the approach from these joints (7 comma-separated radians) instead of the
    /// lab's rest pose (`[arm] rest_q`): where the arm will be when the run starts.
    #[arg(long, value_name = "Q", value_parser = parse_joints, allow_hyphen_values = true)]
    pub from: Option<hitl_hal::Joints>,
    /// Print one JSON object (the full report, or an `error`) instead of the human report.
    #[arg(long)]
    pub json: bool,
}

/// Seven comma-separated joint angles, radians: `--from`.
pub fn parse_joints(s: &str) -> Result<hitl_hal::Joints, String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != hitl_hal::DOF {
        return Err(format!(
            "'{s}': expected {} comma-separated joint angles in radians",
            hitl_hal::DOF
        ));
    }
    let mut q = [0.0; hitl_hal::DOF];
    for (v, p) in q.iter_mut().zip(parts) {
        *v = p
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("'{s}': {p:?} is not a finite number"))?;
    }
    Ok(q)
}

/// The moves a run makes around the trajectory, planned and checked: the approach from `from` to
/// the first setpoint and the retreat from the last to the lab's rest pose. Each is the plan, or
/// why it cannot be made.
pub fn plan_moves(
    table: &SetpointTable,
    lab: &LabConfig,
    from: &hitl_hal::Joints,
) -> [(&'static str, Result<PlannedMove, String>); 2] {
    let last = table.q[table.ticks() - 1];
    let plan = |name, a: &hitl_hal::Joints, b: &hitl_hal::Joints| {
        plan_safe_move(name, a, b, lab, table.rate_hz).map_err(|e| e.to_string())
    };
    [
        ("approach", plan("approach", from, &table.q[0])),
        ("retreat", plan("retreat", &last, &lab.arm.rest_q)),
    ]
}

/// Where `from` is, for people: the rest pose or the joints given.
fn from_name(from: Option<&hitl_hal::Joints>) -> String {
    match from {
        None => "the rest pose ([arm] rest_q)".into(),
        Some(q) => {
            format!("--from {}", q.iter().map(|v| format!("{v}")).collect::<Vec<_>>().join(","))
        }
    }
}

/// The moves' lines for people, and whether all can be made.
pub fn describe_moves(
    moves: &[(&'static str, Result<PlannedMove, String>)],
    from: Option<&hitl_hal::Joints>,
) -> (String, bool) {
    let mut s = String::new();
    let mut ok = true;
    for (name, m) in moves {
        let what = match *name {
            "approach" => format!("approach from {}", from_name(from)),
            _ => "retreat to the rest pose".to_string(),
        };
        match m {
            Ok(m) => {
                let line = m.describe();
                let rest = line.split_once(": ").map_or(line.as_str(), |(_, r)| r);
                let _ = writeln!(s, "  {what}: {rest}");
            }
            Err(e) => {
                ok = false;
                let _ = writeln!(s, "  {what}: NO SAFE PATH: {e}");
            }
        }
    }
    (s, ok)
}

/// The moves as JSON: each plan, or `{"error"}`.
pub fn moves_json(moves: &[(&'static str, Result<PlannedMove, String>)]) -> serde_json::Value {
    let mut v = serde_json::Map::new();
    for (name, m) in moves {
        let value = match m {
            Ok(m) => m.to_json(),
            Err(e) => serde_json::json!({ "error": e }),
        };
        v.insert((*name).to_string(), value);
    }
    serde_json::Value::Object(v)
}

/// A loaded trajectory, its setpoint table and its preflight report.
#[derive(Debug, Clone)]
pub struct Checked {
    pub loaded: Loaded,
    pub table: SetpointTable,
    pub report: PreflightReport,
    /// For a file refused only for velocity, acceleration, jerk or step: the largest
    /// `--speed-scale` that passes (confirmed by a preflight at that value).
    pub speed_scale_to_pass: Option<f64>,
}

/// Why a trajectory could not even be checked (exit 2): the message names the problem.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    #[error(transparent)]
    Config(#[from] hitl_trajectories::lab::ConfigError),
    #[error("{path}: {source}")]
    Trajectory { path: String, source: npz::NpzError },
    #[error("{path}: {source}")]
    Timing { path: String, source: hitl_trajectories::timing::TimingError },
    #[error("{path}: cannot plan the lead-in or lead-out: {source}")]
    Ramp { path: String, source: MotionError },
}

/// Load the lab config (or the default lab).
pub fn load_lab(config: Option<&Path>) -> Result<LabConfig, CheckError> {
    Ok(match config {
        Some(p) => LabConfig::load(p)?,
        None => LabConfig::default(),
    })
}

/// Build the setpoint table of `traj` at `rate_hz` and `speed_scale` with its lead-in and
/// lead-out, and run the preflight over it.
fn table_and_report(
    path: &str,
    traj: &hitl_trajectories::Trajectory,
    lab: &LabConfig,
    rate_hz: f64,
    speed_scale: f64,
    camera: Option<CameraSpec>,
) -> Result<(SetpointTable, PreflightReport), CheckError> {
    let table = SetpointTable::build(traj, rate_hz, speed_scale)
        .map_err(|source| CheckError::Timing { path: path.to_string(), source })?;
    let table = add_ramps(table, lab)
        .map_err(|source| CheckError::Ramp { path: path.to_string(), source })?;
    let mut report = preflight::check(traj, &table, lab);
    if let Some((limit_hz, why)) = camera.and_then(crate::devices::camera::capture_limit) {
        preflight::check_capture_rate(&mut report, &table, limit_hz, &why);
    }
    Ok((table, report))
}

/// `x` rounded down to 4 significant digits, as the number its decimal text reads.
fn floor_4_digits(x: f64) -> f64 {
    let e = x.log10().floor() as i32;
    let unit = 10f64.powi(e - 3);
    let v = (x / unit).floor() * unit;
    let decimals = (3 - e).max(0) as usize;
    format!("{v:.decimals$}").parse().unwrap_or(v)
}

/// The printed `--speed-scale` that passes: the scaling laws' value rounded down to 4
/// significant digits, then checked by a preflight at that value, stepping down by 0.1 % (and
/// rounding down again) while rounding to ticks fails it. When that does not reach a passing
/// value within 2 % (a ramp, which does not follow the laws, breaks a limit), the search goes on
/// in 1 % steps. `None` when no value is confirmed.
fn confirm_speed_scale(
    path: &str,
    traj: &hitl_trajectories::Trajectory,
    lab: &LabConfig,
    rate_hz: f64,
    camera: Option<CameraSpec>,
    exact: f64,
) -> Option<f64> {
    let mut s = floor_4_digits(exact);
    for attempt in 0..120 {
        if s.is_nan() || s <= 0.0 {
            return None;
        }
        match table_and_report(path, traj, lab, rate_hz, s, camera) {
            Ok((_, report)) if report.is_safe() => return Some(s),
            Ok(_) => s = floor_4_digits(s * if attempt < 20 { 0.999 } else { 0.99 }),
            Err(_) => return None,
        }
    }
    None
}

/// Load `traj` (a file without `t` at `waypoint_rate_hz`), build its setpoint table at `rate_hz`
/// and `speed_scale` with its ramps, run the preflight (the captures against `camera`'s rate
/// when one is named), and for a file refused only for scalable limits find the speed scale that
/// passes.
pub fn load_and_check(
    traj: &Path,
    lab: &LabConfig,
    rate_hz: f64,
    speed_scale: f64,
    waypoint_rate_hz: Option<f64>,
    camera: Option<CameraSpec>,
) -> Result<Checked, CheckError> {
    let path = traj.display().to_string();
    let options = npz::LoadOptions { waypoint_rate_hz };
    let loaded = npz::load_with(traj, &options)
        .map_err(|source| CheckError::Trajectory { path: path.clone(), source })?;
    let (table, report) =
        table_and_report(&path, &loaded.trajectory, lab, rate_hz, speed_scale, camera)?;
    let speed_scale_to_pass =
        preflight::speed_scale_to_pass(&table, &report, lab).and_then(|exact| {
            confirm_speed_scale(&path, &loaded.trajectory, lab, rate_hz, camera, exact)
        });
    Ok(Checked { loaded, table, report, speed_scale_to_pass })
}

pub fn run(args: CheckArgs) -> u8 {
    let mut lab_used = LabConfig::default();
    let checked = load_lab(args.config.as_deref()).and_then(|lab| {
        let checked = load_and_check(
            &args.traj,
            &lab,
            args.rate,
            args.speed_scale,
            args.waypoint_rate,
            args.camera,
        );
        lab_used = lab;
        checked
    });
    let checked = match checked {
        Ok(c) => c,
        Err(e) => {
            crate::errln!("hitl check: {e}");
            if args.json {
                let v = serde_json::json!({
                    "file": args.traj.display().to_string(),
                    "safe": false,
                    "error": e.to_string(),
                });
                crate::outln!("{v}");
            }
            return exit::BAD_INPUT;
        }
    };
    let report = &checked.report;
    let from = args.from.unwrap_or(lab_used.arm.rest_q);
    let moves = plan_moves(&checked.table, &lab_used, &from);
    let (moves_text, moves_ok) = describe_moves(&moves, args.from.as_ref());
    let rate_refused_by_run = args.rate > XARM_MAX_SERVO_RATE_HZ;
    if rate_refused_by_run && !args.json {
        crate::errln!(
            "hitl check: warning: --rate {} Hz is above the {XARM_MAX_SERVO_RATE_HZ} Hz an xArm \
             box receives: hitl run refuses it (check at the rate you will run at)",
            args.rate
        );
    }
    if args.json {
        let mut v = serde_json::to_value(report).unwrap_or_default();
        if let Some(obj) = v.as_object_mut() {
            obj.insert("file".into(), args.traj.display().to_string().into());
            obj.insert("load_warnings".into(), checked.loaded.warnings.clone().into());
            obj.insert("rate_refused_by_run".into(), rate_refused_by_run.into());
            obj.insert("lead_in_s".into(), (report.lead_in_ticks as f64 / report.rate_hz).into());
            obj.insert("lead_out_s".into(), (report.lead_out_ticks as f64 / report.rate_hz).into());
            obj.insert("speed_scale_to_pass".into(), checked.speed_scale_to_pass.into());
            obj.insert("moves".into(), moves_json(&moves));
            obj.insert("moves_safe".into(), moves_ok.into());
            obj.insert("approach_from".into(), from.to_vec().into());
        }
        crate::outln!("{v}");
    } else {
        crate::out!("{}", human(&args.traj, &checked, moves_ok));
        crate::out!("  moves between rests (planned around the obstacles, checked every tick):\n");
        crate::out!("{moves_text}");
    }
    if report.is_safe() && moves_ok {
        exit::OK
    } else {
        exit::PREFLIGHT_REFUSED
    }
}

/// The short human report.
fn human(path: &Path, c: &Checked, moves_ok: bool) -> String {
    let r = &c.report;
    let mut s = String::new();
    let verdict = if r.is_safe() && moves_ok {
        "SAFE".to_string()
    } else if r.is_safe() {
        "UNSAFE (the approach or the retreat has no safe path)".to_string()
    } else {
        format!("UNSAFE ({} violation(s))", r.violations.len())
    };
    let _ = writeln!(s, "hitl check {}: {verdict}", path.display());
    let _ = writeln!(
        s,
        "  {} waypoints, {:.3} s at speed scale {}, {} ticks at {} Hz, {} capture(s)",
        r.waypoints, r.duration_s, r.speed_scale, r.ticks, r.rate_hz, r.captures
    );
    if r.lead_in_ticks > 0 || r.lead_out_ticks > 0 {
        let ramp = |ticks: usize, what: &str, how: &str, rest: &str| {
            if ticks == 0 {
                format!("no {what} ({rest})")
            } else {
                format!("{what} {:.3} s ({ticks} ticks) {how}", ticks as f64 / r.rate_hz)
            }
        };
        let _ = writeln!(
            s,
            "  phases: {}, playback of the file's {} ticks, {} (all included above)",
            ramp(
                r.lead_in_ticks,
                "lead-in",
                "from rest into the first waypoint's motion",
                "the file starts at rest"
            ),
            r.ticks - r.lead_in_ticks - r.lead_out_ticks,
            ramp(
                r.lead_out_ticks,
                "lead-out",
                "from the last waypoint's motion to rest",
                "the file ends at rest"
            ),
        );
    }
    for w in c.loaded.warnings.iter().chain(&r.warnings) {
        let _ = writeln!(s, "  warning: {w}");
    }
    let _ = writeln!(s, "  joint limits: table {} (lab config [arm] joint_table)", r.joint_table);
    let _ = writeln!(
        s,
        "  joint  range [rad]        allowed [rad]      |qd| / limit   |qdd| / limit  |jerk| / limit  step [mrad] / limit"
    );
    for j in &r.joints {
        let _ = writeln!(
            s,
            "  {:<5}  {:>7.3} .. {:<7.3}  {:>7.3} .. {:<7.3}  {:>5.2} / {:<5.2}  {:>5.2} / {:<5.2}  {:>6.1} / {:<6.1}  {:>5.2} / {:<5.2}",
            j.joint,
            j.min_rad,
            j.max_rad,
            j.allowed_min_rad,
            j.allowed_max_rad,
            j.peak_velocity,
            j.velocity_limit,
            j.peak_acceleration,
            j.acceleration_limit,
            j.peak_jerk,
            j.jerk_limit,
            j.peak_step_rad * 1e3,
            j.step_limit_rad * 1e3,
        );
    }
    let _ = writeln!(s, "  clearance               min [m]  required  closest    at");
    for cl in &r.clearances {
        let _ = writeln!(
            s,
            "  {:<22} {:>8.3}  {:>8.3}  {:<9}  {:.3} s (tick {})",
            cl.surface, cl.min_m, cl.required_m, cl.capsule, cl.time_s, cl.tick
        );
    }
    let t = &r.tcp_speed;
    let _ = writeln!(
        s,
        "  TCP linear speed       {:>8.3}  {:>8.3}  {:<9}  {:.3} s (tick {})  [m/s]",
        t.peak_m_s, t.limit_m_s, t.point, t.time_s, t.tick
    );
    if let Some(c) = &r.capture_rate {
        let _ = writeln!(
            s,
            "  capture rate           {:>8.3}  {:>8.3}  camera     {:.3} s (tick {})  [Hz]",
            c.peak_hz, c.limit_hz, c.time_s, c.tick
        );
    }
    for v in &r.violations {
        let _ = writeln!(s, "  VIOLATION: {}", v.message);
    }
    if let Some(scale) = c.speed_scale_to_pass {
        let _ = writeln!(
            s,
            "  remedy: --speed-scale {scale} passes (from the scaling laws: velocity, step, TCP \
             speed and capture rate scale with it, acceleration with its square, jerk with its \
             cube; rounded down to 4 digits and confirmed by a preflight at that value)"
        );
    }
    s
}
