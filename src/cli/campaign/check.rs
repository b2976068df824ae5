//! A manifest's values checked when it is loaded, by the same code that checks the flags they
//! become: a case's `hitl plan` and `hitl run` arguments are built as [`super::run`] builds them
//! and parsed with those commands' own clap definitions ([`PlanArgs`], [`RunArgs`] and their
//! value parsers: camera size, scene kind, perception backend, ...), then handed to the checks
//! the commands make next (`hitl plan`'s [`plan::request`] and the planner's request checks in
//! [`planner::orbit_path`]; `hitl run`'s re-registration policy and camera preset). So a value
//! `hitl run --camera-size` would refuse is refused by `hitl campaign list`, with the flag's own
//! message, instead of failing its case an hour into a campaign.

use super::manifest::Case;
use crate::cli::plan::{self, PlanArgs};
use crate::cli::run::RunArgs;
use clap::Parser;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::planner::{self, PlanError, DEFAULT_WAYPOINT_RATE_HZ, MAX_WAYPOINTS};
use std::path::Path;

/// Keys that become `hitl plan` flags.
const PLAN_KEYS: &[&str] = &["preset", "range_m", "arc_deg", "duration_s", "capture_every_s"];
/// Keys that become `hitl run` flags.
const RUN_KEYS: &[&str] = &[
    "scene_kind",
    "camera_preset",
    "camera_size",
    "target",
    "perception",
    "reregister_every",
    "rt_priority",
    "clock",
];

/// `hitl plan`'s flags, parsed as the subcommand parses them.
#[derive(Debug, Parser)]
#[command(name = "hitl plan", no_binary_name = true)]
struct PlanFlags {
    #[command(flatten)]
    args: PlanArgs,
}

/// `hitl run`'s flags, parsed as the subcommand parses them.
#[derive(Debug, Parser)]
#[command(name = "hitl run", no_binary_name = true)]
struct RunFlags {
    #[command(flatten)]
    args: RunArgs,
}

/// Checks case values against the flags' rules, with the manifest's lab.
pub struct Checker {
    lab: LabConfig,
}

/// The first line of a clap error, without its `error: ` prefix.
fn clap_message(e: &clap::Error) -> String {
    let text = e.to_string();
    let line = text.lines().next().unwrap_or_default();
    line.strip_prefix("error: ").unwrap_or(line).to_string()
}

impl Checker {
    /// With the lab `config` names (the built-in lab without one), loaded as `hitl plan` does.
    pub fn new(config: Option<&str>) -> Result<Self, String> {
        let lab = match config {
            Some(path) => LabConfig::load(Path::new(path)).map_err(|e| e.to_string())?,
            None => LabConfig::default(),
        };
        Ok(Checker { lab })
    }

    /// Check `case`'s value of `key` (the case holds it, the defaults and `config`).
    pub fn check(&self, key: &str, case: &Case) -> Result<(), String> {
        if PLAN_KEYS.contains(&key) {
            self.plan(case)?;
        }
        if RUN_KEYS.contains(&key) {
            self.run(case)?;
        }
        Ok(())
    }

    /// The case's `hitl plan` flags through `hitl plan`'s parser and the planner's request checks.
    fn plan(&self, case: &Case) -> Result<(), String> {
        // The planner's waypoint count is `duration * rate + 1`: refuse a duration that would
        // overflow it here (the planner's limit, its constants) rather than hand it over.
        let duration = case.number("duration_s").unwrap_or(0.0);
        if !matches!(
            (duration * DEFAULT_WAYPOINT_RATE_HZ).partial_cmp(&(MAX_WAYPOINTS as f64)),
            Some(std::cmp::Ordering::Less)
        ) {
            return Err(format!(
                "more than {MAX_WAYPOINTS} waypoints at {DEFAULT_WAYPOINT_RATE_HZ} per second \
                 (hitl plan's limit): at most {} s",
                (MAX_WAYPOINTS as f64 - 1.0) / DEFAULT_WAYPOINT_RATE_HZ
            ));
        }
        let (args, _) = super::run::plan_args(case, Path::new("plan.npz"))?;
        let flags = PlanFlags::try_parse_from(args.iter().skip(1)).map_err(|e| clap_message(&e))?;
        let req = plan::request(&flags.args)?;
        match planner::orbit_path(&req, &self.lab) {
            // Whether the orbit fits the arm is the planner's to find when the case plays.
            Ok(_) | Err(PlanError::DoesNotFit { .. }) => Ok(()),
            Err(e @ PlanError::Request(_)) => Err(e.to_string()),
        }
    }

    /// The case's `hitl run` flags through `hitl run`'s parser and its first checks.
    fn run(&self, case: &Case) -> Result<(), String> {
        let args = super::run::run_args(case, Path::new("plan.npz"), Path::new("run.mcap"));
        let flags = RunFlags::try_parse_from(args.iter().skip(1)).map_err(|e| clap_message(&e))?;
        let a = flags.args;
        a.reregister.policy().map_err(|e| e.to_string())?;
        let sim = &a.sim_camera;
        crate::devices::camera::stream_config(
            a.devices.run_camera(),
            &sim.camera_preset,
            sim.camera_size,
        )
        .map_err(|e| e.to_string())?;
        Ok(())
    }
}
