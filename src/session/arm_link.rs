//! The link to the arm: the command client's address, who the arm is (serial number, firmware,
//! and so its joint-limit table), the report reader (on the real-time scheduler just below the
//! loop), the first report, and the box's stop confirmed after a trip.

use super::prepare::violations;
use super::sim_clock::ReaderProgress;
use super::RunError;
use crate::control::stop_supervisor::{supervise_stop, StopConfirmation, StopPolicy};
use crate::control::tick::Outcome;
use crate::devices::arm::{ReportConfig, RunArm, RunArmReports};
use crate::rt::{self, slot::LatestSlot, slot::SlotReader};
use hitl_hal::{ArmReports, ArmState, Clock, Error as _, MonotonicClock};
use hitl_record::{EventKind, SafetyEventMsg, Telemetry};
use hitl_trajectories::joint_table::JointTable;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::SetpointTable;
use hitl_trajectories::{preflight, Trajectory};
use std::net::{IpAddr, SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub(super) fn resolve(host: &str, port: u16) -> Result<SocketAddr, RunError> {
    (host, port)
        .to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| RunError::BadInput(format!("cannot resolve arm address '{host}'")))
}

/// Who the connected arm is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ArmIdentity {
    pub serial: String,
    pub firmware: String,
    /// The joint-limit table the arm enforces, from its serial number as the official SDK picks
    /// it ([`JointTable::for_serial`]).
    pub table: JointTable,
}

/// Ask the arm who it is: serial number and firmware version (a failure is a device fault).
pub(super) fn read_identity(arm: &mut RunArm) -> Result<ArmIdentity, RunError> {
    let serial = arm
        .serial_number()
        .map_err(|e| RunError::Device(format!("reading the arm's serial number: {e}")))?;
    let version =
        arm.version().map_err(|e| RunError::Device(format!("reading the arm's firmware: {e}")))?;
    let table = JointTable::for_serial(&serial);
    Ok(ArmIdentity {
        serial: serial.trim().to_string(),
        firmware: firmware_of(&version).to_string(),
        table,
    })
}

/// The firmware version in a get_version text: boxes answer `axis,type,arm_sn,box_sn,vX.Y.Z`
/// (the last field), older ones the version alone.
fn firmware_of(version: &str) -> &str {
    version.rsplit(',').next().unwrap_or(version).trim()
}

/// The lab as the connected arm sees it: the lab's own table, or the arm's when it is tighter
/// (the tables are nested, so the tighter one is what both allow).
pub(super) fn lab_for_arm(lab: &LabConfig, identity: &ArmIdentity) -> LabConfig {
    let mut arm_lab = lab.clone();
    arm_lab.arm.joint_table = lab.arm.joint_table.tighter(identity.table);
    arm_lab
}

/// On connect, before anything moves: read the arm's identity, print it, and, when the arm's
/// joint table is tighter than the lab's, ask the one question the table changes again: the
/// trajectory's joint positions against it (exit 3 naming the joint and the table; every other
/// rule's answer from [`super::prepare`] stands). Returns the lab the approach must be planned
/// and checked in.
pub(super) fn identify_and_check(
    arm: &mut RunArm,
    lab: &LabConfig,
    traj: &Trajectory,
    table: &SetpointTable,
) -> Result<LabConfig, RunError> {
    let identity = read_identity(arm)?;
    let arm_lab = lab_for_arm(lab, &identity);
    crate::errln!(
        "arm: serial {}, firmware {}, joint table {} (lab: {}; checking against {})",
        if identity.serial.is_empty() { "(none)" } else { &identity.serial },
        if identity.firmware.is_empty() { "(none)" } else { &identity.firmware },
        identity.table,
        lab.arm.joint_table,
        arm_lab.arm.joint_table
    );
    if arm_lab.arm.joint_table == lab.arm.joint_table {
        return Ok(arm_lab);
    }
    let refused = preflight::check_joint_limits(table, traj.len(), &arm_lab);
    if !refused.is_empty() {
        return Err(RunError::Refused(format!(
            "the connected arm (serial {}) enforces joint table {}:\n{}",
            identity.serial,
            identity.table,
            violations(&refused)
        )));
    }
    Ok(arm_lab)
}

/// After the loop, on the session thread: when the run tripped, repeat the box's stop every
/// 100 ms until a report shows state 4, or 3 s pass ([`supervise_stop`]); print the result and
/// record it as a `/safety/event` (kind `other`, detail `box stop confirmed: ...` or `box stop
/// NOT confirmed: ...`). A completed run has nothing to stop (`None`). `reports` is the session's
/// tap of the report slot; the reader thread must still be running. `advance` runs before each
/// look at the reports: on a simulated clock it moves the world on by one period.
pub(super) fn confirm_stop(
    arm: &mut RunArm,
    reports: &mut SlotReader<ArmState>,
    outcome: &Outcome,
    clock: &MonotonicClock,
    record: Option<&Telemetry>,
    advance: &mut dyn FnMut(),
) -> Option<StopConfirmation> {
    let Outcome::Tripped { .. } = outcome else {
        return None;
    };
    let mut latest = || {
        advance();
        reports.latest().0
    };
    let confirmation = supervise_stop(arm, &mut latest, clock, StopPolicy::default());
    let line = confirmation.describe();
    crate::errln!("{line}");
    if let Some(t) = record {
        t.push_event(SafetyEventMsg::text(clock.now_ns(), EventKind::Other, line));
    }
    Some(confirmation)
}

/// The report reader thread: reports into the latest-value slot until told to stop or the
/// stream fails (then the tick's watchdog trips).
///
/// The reports are the loop's only view of the arm, so when the loop runs on SCHED_FIFO the
/// reader runs just below it (`fifo_priority - 1`): perception, rendering or recording on the
/// normal scheduler cannot make the watchdog see a silence the arm did not cause. Refused, it
/// stays on the normal scheduler (the loop's own report already says real-time was refused).
pub(super) fn spawn_report_reader(
    mut reader: RunArmReports,
    slot: LatestSlot<ArmState>,
    stop: Arc<AtomicBool>,
    progress: Arc<ReaderProgress>,
    fifo_priority: Option<i32>,
    simulated: bool,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new().name("hitl-reports".into()).spawn(move || {
        if let Some(p) = fifo_priority {
            let _ = rt::os::set_fifo_priority((p - 1).max(1));
        }
        while !stop.load(Ordering::Acquire) {
            match reader.next_report() {
                Ok(state) => {
                    slot.publish(state);
                    progress.published.fetch_add(1, Ordering::AcqRel);
                }
                // On a simulated clock a read timeout is host time passing while simulated
                // time stands still (a long render or estimate), not a silent box.
                Err(e) if simulated && e.kind() == hitl_hal::ErrorKind::Timeout => continue,
                Err(_) => break,
            }
        }
        progress.ended.store(true, Ordering::Release);
    })
}

/// Wait for the first arm report (the arm is alive and we know where it is); `prime` runs before
/// each look (on a simulated clock it has the stub write the reports due now).
pub(super) fn first_report(
    reader: &mut rt::slot::SlotReader<ArmState>,
    timeout: Duration,
    prime: impl Fn(),
) -> Option<ArmState> {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        prime();
        if let (Some(state), true) = reader.latest() {
            return Some(state);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    None
}

pub(super) fn connect_reports(
    host: IpAddr,
    port: u16,
    codes_port: Option<u16>,
    clock: MonotonicClock,
) -> Result<RunArmReports, RunError> {
    let config = ReportConfig { port: Some(port), codes_port, clock, ..ReportConfig::default() };
    RunArmReports::connect(host, config)
        .map_err(|e| RunError::Device(format!("arm report stream at {host}:{port}: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_firmware_is_the_last_field_of_the_version_text() {
        assert_eq!(firmware_of("7,7,XS1305HITL01,XX1305HITL01,v2.5.0"), "v2.5.0");
        assert_eq!(firmware_of("v1.9.0"), "v1.9.0");
        assert_eq!(firmware_of(""), "");
    }

    #[test]
    fn the_tighter_table_is_checked_on_connect() {
        let id = |serial: &str| ArmIdentity {
            serial: serial.into(),
            firmware: "v2.5.0".into(),
            table: JointTable::for_serial(serial),
        };
        let mut lab = LabConfig::default();
        lab.arm.joint_table = JointTable::Xarm7Legacy;
        assert_eq!(
            lab_for_arm(&lab, &id("XS1305HITL01")).arm.joint_table,
            JointTable::Xarm7Current
        );
        assert_eq!(lab_for_arm(&lab, &id("XS1200000001")).arm.joint_table, JointTable::Xarm7Legacy);
        lab.arm.joint_table = JointTable::Xarm7Current;
        assert_eq!(
            lab_for_arm(&lab, &id("XS1200000001")).arm.joint_table,
            JointTable::Xarm7Current
        );
    }
}
