//! Before anything connects: the trajectory loaded (or taken as handed over in memory),
//! time-parametrised and preflighted, with where it came from; and the
//! moves between rests (the approach from wherever the arm stands, the retreat to the rest pose)
//! planned around the lab's obstacles and preflighted by the same rules.

use super::{ArmTarget, RunError, RunRequest, TrajectorySource};
use crate::control::motion::add_ramps;
use crate::control::planned_move::{plan_safe_move, PlannedMove};
use hitl_hal::Joints;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::{SetpointTable, XARM_MAX_SERVO_RATE_HZ};
use hitl_trajectories::{npz, preflight, Trajectory};
use sha2::Digest as _;

/// The preflight's violations, one per line.
pub(super) fn violations(violations: &[preflight::Violation]) -> String {
    let lines: Vec<String> = violations.iter().map(|v| format!("  - {}", v.message)).collect();
    lines.join("\n")
}

/// Refuse a control rate the arm cannot take: an xArm control box receives servo_j at most at
/// [`XARM_MAX_SERVO_RATE_HZ`]; faster, the box queues or drops setpoints and the loop's timing
/// no longer means what the preflight checked. The stub obeys the same rule, so a run that
/// passes on the stub is a run a real box can take.
pub(super) fn check_rate(req: &RunRequest) -> Result<(), RunError> {
    if req.rate_hz > XARM_MAX_SERVO_RATE_HZ {
        let target = match &req.target {
            ArmTarget::Remote { host } => format!("the arm at {host}"),
            ArmTarget::Stub { .. } => "the stub (which plays a control box)".to_string(),
        };
        return Err(RunError::BadInput(format!(
            "--rate {} Hz is more than {target} can take: an xArm control box receives servo_j \
             setpoints at most {XARM_MAX_SERVO_RATE_HZ} Hz (UFACTORY); use --rate \
             {XARM_MAX_SERVO_RATE_HZ} or less",
            req.rate_hz
        )));
    }
    Ok(())
}

/// Where a run's trajectory came from, for the recording's `run` metadata.
#[derive(Debug, Clone, Default)]
pub(super) struct Provenance {
    /// The file's path, or what an in-memory trajectory is; empty when parking.
    pub name: String,
    /// SHA-256 of the file's bytes, or of the NPZ bytes an in-memory trajectory would be saved
    /// as (`npz::to_bytes`, compressed: what `hitl calibrate` used to write); hex, empty when
    /// parking (and for a file when nothing is recorded).
    pub sha256: String,
}

impl Provenance {
    /// Nothing played (`hitl park`).
    pub fn none() -> Self {
        Self::default()
    }

    fn of_bytes(name: String, bytes: &[u8]) -> Self {
        let sha = sha2::Sha256::digest(bytes);
        Self { name, sha256: sha.iter().map(|b| format!("{b:02x}")).collect() }
    }
}

/// The trajectory a run plays: loaded, time-parametrised, preflighted once (every rule over the
/// setpoint table, captures against the camera's rate), with where it came from.
pub(super) struct Prepared {
    pub traj: Trajectory,
    pub table: SetpointTable,
    pub source: Provenance,
}

/// Load the file, or validate the trajectory handed over in memory, as `req.trajectory` says.
fn load(req: &RunRequest) -> Result<(Trajectory, Provenance), RunError> {
    match &req.trajectory {
        TrajectorySource::File { path, waypoint_rate_hz } => {
            let options = npz::LoadOptions { waypoint_rate_hz: *waypoint_rate_hz };
            let loaded = npz::load_with(path, &options)
                .map_err(|e| RunError::BadInput(format!("{}: {e}", path.display())))?;
            for warning in &loaded.warnings {
                crate::errln!("warning: {warning}");
            }
            // The file's bytes, read again only for a recording's hash.
            let name = path.display().to_string();
            let source = match &req.record {
                Some(_) => Provenance::of_bytes(name, &std::fs::read(path).unwrap_or_default()),
                None => Provenance { name, sha256: String::new() },
            };
            Ok((loaded.trajectory, source))
        }
        TrajectorySource::InMemory { trajectory, name } => {
            // The same validation a file gets before it is written or played.
            let bytes = npz::to_bytes(trajectory, true)
                .map_err(|e| RunError::BadInput(format!("{name}: {e}")))?;
            Ok((trajectory.as_ref().clone(), Provenance::of_bytes(name.clone(), &bytes)))
        }
        TrajectorySource::Park => {
            Err(RunError::BadInput("parking has no trajectory to load".into()))
        }
    }
}

/// Load, time-parametrise (with the lead-in and lead-out of a file that starts or ends moving)
/// and preflight the trajectory, captures against the camera's rate included: refuse before
/// anything is opened. The one full preflight of a run: later steps ask only what differs (the
/// connected arm's joint table, `arm_link`; the planned moves, [`plan_move_between`]).
pub(super) fn prepare(req: &RunRequest) -> Result<Prepared, RunError> {
    check_rate(req)?;
    let (traj, source) = load(req)?;
    let table = SetpointTable::build(&traj, req.rate_hz, req.speed_scale)
        .map_err(|e| RunError::BadInput(e.to_string()))?;
    let table = add_ramps(table, &req.lab)
        .map_err(|e| RunError::Refused(format!("  - lead-in/lead-out: {e}")))?;
    let mut report = preflight::check(&traj, &table, &req.lab);
    if let Some((limit_hz, why)) = crate::devices::camera::capture_limit(req.camera) {
        preflight::check_capture_rate(&mut report, &table, limit_hz, &why);
    }
    if !report.is_safe() {
        return Err(RunError::Refused(violations(&report.violations)));
    }
    Ok(Prepared { traj, table, source })
}

/// Plan the move `name` (`approach`, `retreat`) between two rests around the lab's obstacles and
/// check every tick of it like a trajectory ([`plan_safe_move`]); refused (exit 3) naming the
/// obstacle in the way.
pub(super) fn plan_move_between(
    name: &'static str,
    from: &Joints,
    to: &Joints,
    lab: &LabConfig,
    rate_hz: f64,
) -> Result<PlannedMove, RunError> {
    plan_safe_move(name, from, to, lab, rate_hz).map_err(|e| {
        RunError::Refused(match name {
            "approach" => format!(
                "the approach from the arm's pose to the trajectory's first setpoint has no safe \
                 path:\n  - {e}"
            ),
            "retreat" => format!(
                "the retreat from the trajectory's last setpoint to the rest pose ([arm] rest_q) \
                 has no safe path (--no-retreat leaves the arm where the trajectory ends):\n  - {e}"
            ),
            other => format!("the {other} has no safe path:\n  - {e}"),
        })
    })
}
