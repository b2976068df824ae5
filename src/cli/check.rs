//! `hitl check`: the preflight on its own. Loads and validates the NPZ, builds the setpoint table
//! at the playback rate and speed scale, runs every preflight rule at every tick, and prints a
//! short report (or one JSON object). Exit 0 safe, 3 valid but unsafe, 2 bad file, flags or
//! config. `hitl run` applies the same rules through [`load_and_check`] before anything moves.

use crate::exit;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::npz::{self, Loaded};
use hitl_trajectories::preflight::{self, PreflightReport};
use hitl_trajectories::timing::{SetpointTable, DEFAULT_RATE_HZ};
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
    /// Print one JSON object (the full report, or an `error`) instead of the human report.
    #[arg(long)]
    pub json: bool,
}

/// A loaded trajectory, its setpoint table and its preflight report.
#[derive(Debug, Clone)]
pub struct Checked {
    pub loaded: Loaded,
    pub table: SetpointTable,
    pub report: PreflightReport,
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
}

/// Load the lab config (or the default lab).
pub fn load_lab(config: Option<&Path>) -> Result<LabConfig, CheckError> {
    Ok(match config {
        Some(p) => LabConfig::load(p)?,
        None => LabConfig::default(),
    })
}

/// Load `traj`, build its setpoint table at `rate_hz` and `speed_scale`, run the preflight.
pub fn load_and_check(
    traj: &Path,
    lab: &LabConfig,
    rate_hz: f64,
    speed_scale: f64,
) -> Result<Checked, CheckError> {
    let path = traj.display().to_string();
    let loaded =
        npz::load(traj).map_err(|source| CheckError::Trajectory { path: path.clone(), source })?;
    let table = SetpointTable::build(&loaded.trajectory, rate_hz, speed_scale)
        .map_err(|source| CheckError::Timing { path, source })?;
    let report = preflight::check(&loaded.trajectory, &table, lab);
    Ok(Checked { loaded, table, report })
}

pub fn run(args: CheckArgs) -> u8 {
    let checked = load_lab(args.config.as_deref())
        .and_then(|lab| load_and_check(&args.traj, &lab, args.rate, args.speed_scale));
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
    if args.json {
        let mut v = serde_json::to_value(report).unwrap_or_default();
        if let Some(obj) = v.as_object_mut() {
            obj.insert("file".into(), args.traj.display().to_string().into());
            obj.insert("load_warnings".into(), checked.loaded.warnings.clone().into());
        }
        crate::outln!("{v}");
    } else {
        crate::out!("{}", human(&args.traj, &checked));
    }
    if report.is_safe() {
        exit::OK
    } else {
        exit::PREFLIGHT_REFUSED
    }
}

/// The short human report.
fn human(path: &Path, c: &Checked) -> String {
    let r = &c.report;
    let mut s = String::new();
    let verdict = if r.is_safe() {
        "SAFE".to_string()
    } else {
        format!("UNSAFE ({} violation(s))", r.violations.len())
    };
    let _ = writeln!(s, "hitl check {}: {verdict}", path.display());
    let _ = writeln!(
        s,
        "  {} waypoints, {:.3} s at speed scale {}, {} ticks at {} Hz, {} capture(s)",
        r.waypoints, r.duration_s, r.speed_scale, r.ticks, r.rate_hz, r.captures
    );
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
    for v in &r.violations {
        let _ = writeln!(s, "  VIOLATION: {}", v.message);
    }
    s
}
