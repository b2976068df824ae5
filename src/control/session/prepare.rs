//! Before anything connects: the trajectory loaded, time-parametrised and preflighted, and the
//! approach from wherever the arm stands planned and preflighted by the same rules.

use super::{ArmTarget, RunError, RunRequest};
use crate::control::motion::{add_ramps, plan_move, MoveLimits};
use crate::control::setpoint::Setpoint;
use hitl_hal::Joints;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::{SetpointTable, XARM_MAX_SERVO_RATE_HZ};
use hitl_trajectories::{npz, preflight, Trajectory};

/// The preflight's violations, one per line.
pub(super) fn violations(report: &preflight::PreflightReport) -> String {
    let lines: Vec<String> =
        report.violations.iter().map(|v| format!("  - {}", v.message)).collect();
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

/// Load, time-parametrise (with the lead-in and lead-out of a file that starts or ends moving)
/// and preflight the trajectory, captures against the camera's rate included: refuse before
/// anything is opened.
pub(super) fn prepare(req: &RunRequest) -> Result<(Trajectory, SetpointTable), RunError> {
    check_rate(req)?;
    let options = npz::LoadOptions { waypoint_rate_hz: req.waypoint_rate_hz };
    let loaded = npz::load_with(&req.trajectory, &options)
        .map_err(|e| RunError::BadInput(format!("{}: {e}", req.trajectory.display())))?;
    for warning in &loaded.warnings {
        crate::errln!("warning: {warning}");
    }
    let traj = loaded.trajectory;
    let table = SetpointTable::build(&traj, req.rate_hz, req.speed_scale)
        .map_err(|e| RunError::BadInput(e.to_string()))?;
    let table = add_ramps(table, &req.lab)
        .map_err(|e| RunError::Refused(format!("  - lead-in/lead-out: {e}")))?;
    let mut report = preflight::check(&traj, &table, &req.lab);
    if let Some((limit_hz, why)) = crate::devices::camera::capture_limit(req.camera) {
        preflight::check_capture_rate(&mut report, &table, limit_hz, &why);
    }
    if !report.is_safe() {
        return Err(RunError::Refused(violations(&report)));
    }
    Ok((traj, table))
}

/// A setpoint table for a planned move, so the approach goes through the same preflight rules.
pub(super) fn approach_table(
    approach: &[Setpoint],
    start: &Joints,
    rate_hz: f64,
) -> (Trajectory, SetpointTable) {
    let dt = 1.0 / rate_hz;
    let mut q = vec![*start];
    q.extend(approach.iter().map(|s| s.q));
    let mut qd = vec![[0.0; 7]];
    qd.extend(approach.iter().map(|s| s.qd));
    let mut qdd = vec![[0.0; 7]];
    qdd.extend(approach.iter().map(|s| s.qdd));
    let jerk = (0..qdd.len())
        .map(|k| {
            let prev = qdd[k.saturating_sub(1)];
            std::array::from_fn(|j| (qdd[k][j] - prev[j]) / dt)
        })
        .collect();
    let ticks = q.len();
    let traj = Trajectory {
        qpos: vec![*start, q[ticks - 1]],
        t: vec![0.0, (ticks - 1).max(1) as f64 * dt],
        ..Default::default()
    };
    let table = SetpointTable {
        rate_hz,
        dt,
        speed_scale: 1.0,
        time_scale: 1.0,
        duration_s: (ticks - 1) as f64 * dt,
        q,
        qd,
        qdd,
        jerk,
        waypoint_ticks: vec![0, ticks - 1],
        captures: Vec::new(),
        light: None,
        lead_in_ticks: 0,
        lead_out_ticks: 0,
    };
    (traj, table)
}

/// Plan the slow move from the arm's pose to the first waypoint and check it like a trajectory.
///
/// Two shapes are tried, each a chain of Ruckig rest-to-rest moves: the direct joint-space move,
/// then one that first turns base and wrist while shoulder and elbow stay where they are (the arm
/// keeps its reach) and extends only at the end. The first that passes every preflight rule is
/// taken; when none does, the run is refused with the direct move's violations.
pub(super) fn plan_approach(
    start: &Joints,
    table: &SetpointTable,
    lab: &LabConfig,
) -> Result<Vec<Setpoint>, RunError> {
    let l = &lab.limits;
    let limits = MoveLimits::uniform(
        l.approach_velocity_rad_s,
        l.approach_acceleration_rad_s2,
        l.approach_jerk_rad_s3,
    );
    let goal = table.q[0];
    let mut keep_reach = goal;
    keep_reach[1] = start[1];
    keep_reach[3] = start[3];
    let shapes: [&[Joints]; 2] = [&[goal], &[keep_reach, goal]];
    let mut first_refusal = None;
    for shape in shapes {
        let mut path = Vec::new();
        let mut from = *start;
        for via in shape {
            let leg = plan_move(&from, via, &limits, table.dt)
                .map_err(|e| RunError::Refused(format!("approach: {e}")))?;
            path.extend(leg);
            from = *via;
        }
        if path.is_empty() {
            return Ok(path);
        }
        let (traj, approach_table) = approach_table(&path, start, table.rate_hz);
        let report = preflight::check(&traj, &approach_table, lab);
        if report.is_safe() {
            return Ok(path);
        }
        first_refusal.get_or_insert_with(|| violations(&report));
    }
    Err(RunError::Refused(format!(
        "the approach from the arm's pose to the first waypoint is unsafe (move the arm nearer \
         the trajectory's start first):\n{}",
        first_refusal.unwrap_or_default()
    )))
}
