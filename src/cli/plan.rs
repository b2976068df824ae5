//! `hitl plan`: plan an orbital trajectory (ROE -> HCW -> lab frame -> IK), preflight it, and
//! write it as NPZ. See docs/planner.md.
//!
//! Before writing, the moves a run makes around the plan are planned and checked as `hitl check`
//! does: the approach from the lab's rest pose (`[arm] rest_q`) and the retreat back to it.
//!
//! Exit codes: 0 written; 2 bad flags or configuration, or the scaled orbit does not fit the
//! arm's reachable, collision-free volume (the message names the feasible arcs and the `--arc`
//! that plans the longest); 3 the planned motion failed preflight, or the approach or retreat has
//! no safe path (nothing written).

use crate::exit;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::orbit::{Preset, PAPER_TIME_SCALE};
use hitl_trajectories::planner::{self, PlanError, PlanRequest, Timing};
use hitl_trajectories::{npz, preflight, timing};
use std::io::Write;
use std::path::PathBuf;

/// Flags of `hitl plan`.
#[derive(Debug, clap::Args)]
pub struct PlanArgs {
    /// Relative motion: `flyaround` (delta e_x = delta i_y = r/a) or `station-keeping`
    /// (delta lambda = r/a, a fixed point along-track).
    #[arg(long, value_name = "NAME")]
    pub preset: String,
    /// Nominal chaser-target range r in real metres.
    #[arg(long, value_name = "R", default_value_t = 50.0)]
    pub range_m: f64,
    /// Total playback duration in seconds (all revolutions, ramps included). Without it the
    /// orbit plays at --time-scale.
    #[arg(long, value_name = "S")]
    pub duration_s: Option<f64>,
    /// Orbit time over playback time when --duration-s is not given (the paper's tau).
    #[arg(long, value_name = "TAU", default_value_t = PAPER_TIME_SCALE)]
    pub time_scale: f64,
    /// Number of waypoints, evenly spaced in time (default: 10 per second, plus one).
    #[arg(long, value_name = "N")]
    pub waypoints: Option<usize>,
    /// Revolutions (passes over --arc); the direction alternates after each (windup rule).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub revolutions: usize,
    /// Capture a frame at every k-th waypoint.
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub capture_every: usize,
    /// Light level (0-1) at every waypoint.
    #[arg(long, value_name = "LEVEL", default_value_t = 1.0)]
    pub light: f32,
    /// Ramp-up and ramp-down time of each revolution, seconds (rest to rest).
    #[arg(long, value_name = "S", default_value_t = 2.0)]
    pub ramp_s: f64,
    /// Play only an arc of argument of latitude, degrees FROM:TO (FROM < TO <= FROM + 360),
    /// e.g. the feasible arc a refused plan proposes.
    #[arg(long, value_name = "FROM:TO")]
    pub arc: Option<String>,
    /// RTN-to-base rotation as roll,pitch,yaw degrees (z-y-x) instead of the documented default.
    #[arg(long, value_name = "R,P,Y", allow_hyphen_values = true)]
    pub rtn_rpy_deg: Option<String>,
    /// Sun direction in ECI as X,Y,Z (default 1,0,0: the Sun at the March equinox).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub sun_eci: Option<String>,
    /// Workspace fill fraction alpha of the scale alpha * d_arm / r.
    #[arg(long, value_name = "A", default_value_t = planner::mapping::PAPER_ALPHA)]
    pub alpha: f64,
    /// Practical arm reach d_arm of the scale, metres.
    #[arg(long, value_name = "M", default_value_t = planner::mapping::PAPER_D_ARM_M)]
    pub d_arm_m: f64,
    /// Control rate the preflight checks the plan at, Hz.
    #[arg(long, value_name = "HZ", default_value_t = timing::DEFAULT_RATE_HZ)]
    pub rate: f64,
    /// Output file (default: PRESET-RANGEm.npz in the current folder).
    #[arg(long, value_name = "FILE.npz")]
    pub out: Option<PathBuf>,
    /// Write the NPZ uncompressed (savez instead of savez_compressed).
    #[arg(long)]
    pub uncompressed: bool,
    /// Lab configuration (TOML); default: the built-in DreamSat-Bench lab.
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Print the summary as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

fn parse_list<const N: usize>(flag: &str, text: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != N {
        return Err(format!("{flag} {text:?}: expected {N} comma-separated numbers"));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p
            .trim()
            .parse::<f64>()
            .map_err(|_| format!("{flag} {text:?}: {p:?} is not a number"))?;
    }
    Ok(out)
}

fn parse_arc(text: &str) -> Result<(f64, f64), String> {
    let (a, b) = text
        .split_once(':')
        .ok_or_else(|| format!("--arc {text:?}: expected FROM:TO in degrees"))?;
    let num = |s: &str| {
        s.trim().parse::<f64>().map_err(|_| format!("--arc {text:?}: {s:?} is not a number"))
    };
    Ok((num(a)?, num(b)?))
}

/// The request the flags describe.
pub fn request(args: &PlanArgs) -> Result<PlanRequest, String> {
    let preset = Preset::from_name(&args.preset).ok_or_else(|| {
        format!("unknown --preset {:?}: use flyaround or station-keeping", args.preset)
    })?;
    let timing = match args.duration_s {
        Some(d) => Timing::DurationS(d),
        None => Timing::TimeScale(args.time_scale),
    };
    let mut req = PlanRequest {
        preset,
        range_m: args.range_m,
        timing,
        waypoints: args.waypoints,
        revolutions: args.revolutions,
        capture_every: args.capture_every,
        light: args.light,
        ramp_s: args.ramp_s,
        alpha: args.alpha,
        d_arm_m: args.d_arm_m,
        ..PlanRequest::default()
    };
    if let Some(a) = &args.arc {
        req.arc_deg = Some(parse_arc(a)?);
    }
    if let Some(r) = &args.rtn_rpy_deg {
        req.rtn_rpy_deg = Some(parse_list::<3>("--rtn-rpy-deg", r)?);
    }
    if let Some(s) = &args.sun_eci {
        req.sun_eci = parse_list::<3>("--sun-eci", s)?;
    }
    Ok(req)
}

fn print_summary(s: &planner::PlanSummary, out: &std::path::Path) {
    crate::outln!("wrote {}", out.display());
    crate::outln!(
        "  {} at {} m: {} waypoints ({} captures), {:.1} s, {} revolution(s)",
        s.preset,
        s.range_m,
        s.waypoints,
        s.captures,
        s.duration_s,
        s.passes
    );
    crate::outln!(
        "  scale {:.4e} lab m per real m; camera {:.3}-{:.3} m from the target",
        s.scale,
        s.min_camera_target_m,
        s.max_camera_target_m
    );
    crate::outln!("  arc of u: {:.1}-{:.1} deg (feasible in full)", s.arc_deg.0, s.arc_deg.1);
    crate::outln!(
        "  peak joint speeds (rad/s): {}",
        s.peak_joint_speed_rad_s.iter().map(|v| format!("{v:.3}")).collect::<Vec<_>>().join(" ")
    );
    crate::outln!(
        "  IK residuals: {:.2e} m, {:.2e} deg; nearest obstacle {:.1} mm beyond its margin",
        s.max_ik_pos_err_m,
        s.max_ik_rot_err_deg,
        s.min_clearance_m * 1e3
    );
    crate::outln!("  Sun phase {:.1}-{:.1} deg", s.sun_phase_deg.0, s.sun_phase_deg.1);
}

pub fn run(args: PlanArgs) -> u8 {
    let req = match request(&args) {
        Ok(r) => r,
        Err(e) => {
            crate::errln!("hitl plan: {e}");
            return exit::BAD_INPUT;
        }
    };
    let lab = match &args.config {
        Some(path) => match LabConfig::load(path) {
            Ok(l) => l,
            Err(e) => {
                crate::errln!("hitl plan: {e}");
                return exit::BAD_INPUT;
            }
        },
        None => LabConfig::default(),
    };
    let mut progress = |done: usize, total: usize| {
        if !args.json {
            crate::err!("\rhitl plan: inverse kinematics, candidate {done}/{total}");
            let _ = std::io::stderr().flush();
        }
    };
    let result = planner::plan(&req, &lab, &mut progress);
    if !args.json {
        crate::errln!();
    }
    let plan = match result {
        Ok(p) => p,
        Err(PlanError::Request(m)) => {
            crate::errln!("hitl plan: {m}");
            return exit::BAD_INPUT;
        }
        Err(e @ PlanError::DoesNotFit { .. }) => {
            crate::errln!("hitl plan: refused: {e}");
            return exit::BAD_INPUT;
        }
    };
    let table = match timing::SetpointTable::build(&plan.trajectory, args.rate, 1.0) {
        Ok(t) => t,
        Err(e) => {
            crate::errln!(
                "hitl plan: the plan cannot be time-parametrised at {} Hz: {e}",
                args.rate
            );
            return exit::PREFLIGHT_REFUSED;
        }
    };
    let report = preflight::check(&plan.trajectory, &table, &lab);
    if !report.is_safe() {
        crate::errln!("hitl plan: the planned motion fails preflight, nothing written:");
        for v in &report.violations {
            crate::errln!("  {}", v.message);
        }
        // Too fast for the lab's speed limits: say how long the plan would have to last.
        let ratio = plan
            .summary
            .peak_joint_speed_rad_s
            .iter()
            .zip(lab.limits.velocity_rad_s)
            .map(|(v, lim)| v / lim)
            .fold(0.0, f64::max);
        if ratio > 0.9 {
            let longer = (plan.summary.duration_s * ratio / 0.8).ceil();
            crate::errln!(
                "  the waypoints alone reach {:.0} % of the speed limit: try --duration-s {longer}",
                ratio * 100.0
            );
        }
        return exit::PREFLIGHT_REFUSED;
    }
    let moves = super::check::plan_moves(&table, &lab, &lab.arm.rest_q);
    let (moves_text, moves_ok) = super::check::describe_moves(&moves, None);
    if !moves_ok {
        crate::errln!(
            "hitl plan: the plan cannot be reached from the rest pose, nothing written:\n{moves_text}"
        );
        return exit::PREFLIGHT_REFUSED;
    }
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}-{}m.npz", req.preset.name(), args.range_m)));
    if let Err(e) = npz::save(&out, &plan.trajectory, !args.uncompressed) {
        crate::errln!("hitl plan: cannot write {}: {e}", out.display());
        return exit::BAD_INPUT;
    }
    if args.json {
        let v = serde_json::json!({
            "out": out.display().to_string(),
            "summary": plan.summary,
            "moves": super::check::moves_json(&moves),
        });
        crate::outln!("{v}");
    } else {
        print_summary(&plan.summary, &out);
        crate::out!("{moves_text}");
    }
    exit::OK
}
