//! `hitl probe --arm HOST[:PORT]`: the arm's command port (serial number, firmware, state, codes,
//! the joint-limit table it enforces) and its report ports, which a run also needs (the real
//! report at 100 Hz: joint positions, state, mode; the normal report: error and warning codes).
//! Only reads are sent; nothing is enabled and nothing moves.

use crate::outln;
use hitl_drivers::xarm::codes::{error_name, warning_name};
use hitl_drivers::xarm::{ClientConfig, ReportConfig, ReportKind, ReportReader, XarmClient};
use hitl_hal::{Arm as _, ArmReports as _};
use hitl_trajectories::joint_table::JointTable;
use std::time::Duration;

/// What the box's state number means (xArm developer manual).
fn state_name(state: u8) -> &'static str {
    match state {
        1 => "moving",
        2 => "sleeping (ready)",
        3 => "paused",
        4 => "stopped",
        5 => "stopped (mode or state being changed)",
        6 => "stopped (collision or error)",
        _ => "unknown",
    }
}

/// What the box's mode number means.
fn mode_name(mode: u8) -> &'static str {
    match mode {
        0 => "position",
        1 => "servo",
        2 => "joint teaching",
        4 => "joint velocity",
        5 => "cartesian velocity",
        6 => "joint online trajectory",
        7 => "cartesian online trajectory",
        _ => "unknown",
    }
}

/// Probe the arm at `host` (HOST or IP:PORT for the command port), its real report at
/// `report_port` and its normal report (codes) two ports below, as on a box (30003, 30001).
pub(super) fn probe_arm(host: &str, report_port: u16) -> Result<(), String> {
    let config = ClientConfig::default();
    let connected = match host.parse::<std::net::SocketAddr>() {
        Ok(addr) => XarmClient::connect(addr, config),
        Err(_) => XarmClient::connect_host(host, config),
    };
    let mut arm = connected.map_err(|e| e.to_string())?;
    let serial = arm.serial_number().map_err(|e| format!("serial number: {e}"))?;
    let version = arm.version().map_err(|e| format!("firmware version: {e}"))?;
    let state = arm.state().map_err(|e| format!("state: {e}"))?;
    let (error, warning) = arm.codes().map_err(|e| format!("error codes: {e}"))?;
    let table = JointTable::for_serial(&serial);
    outln!("arm {host}: serial {serial}, firmware {version}");
    outln!("  command port {}: answered", arm.peer());
    outln!("  state {state}, error code {error}, warning code {warning}");
    if error != 0 {
        outln!("  error {error}: {}", error_name(error).unwrap_or("not named by the SDK"));
    }
    if warning != 0 {
        outln!("  warning {warning}: {}", warning_name(warning).unwrap_or("not named by the SDK"));
    }
    let limits = table
        .limits()
        .iter()
        .enumerate()
        .map(|(j, (lo, hi))| format!("J{} {:.4}..{:.4}", j + 1, lo, hi))
        .collect::<Vec<_>>()
        .join(", ");
    outln!("  joint-limit table {table}: {limits} rad");

    let codes_port = report_port.saturating_sub(2);
    let ip = arm.peer().ip();
    let report_config = ReportConfig {
        kind: ReportKind::Real,
        port: Some(report_port),
        codes_port: Some(codes_port),
        connect_timeout: Duration::from_secs(2),
        read_timeout: Duration::from_secs(1),
        ..ReportConfig::default()
    };
    let mut reports = ReportReader::connect(ip, report_config).map_err(|e| {
        format!("report ports {ip}:{report_port} (real) and {codes_port} (normal, codes): {e}")
    })?;
    // Two reports: the codes side connection has had a moment to deliver its first frame.
    let _ = reports.next_report().map_err(|e| format!("report port {report_port}: {e}"))?;
    std::thread::sleep(Duration::from_millis(250));
    let s = reports.next_report().map_err(|e| format!("report port {report_port}: {e}"))?;
    outln!(
        "  report ports {report_port} (real, joints, state, mode) and {codes_port} (normal, \
         codes): answered"
    );
    outln!(
        "  reported: state {} ({}), mode {} ({}), error {}, warning {}",
        s.state,
        state_name(s.state),
        s.mode,
        mode_name(s.mode),
        s.error_code,
        s.warn_code
    );
    // A joint a hair below zero prints as 0.0000, not -0.0000.
    let tidy = |q: f64| if q.abs() < 5e-5 { 0.0 } else { q };
    let q =
        s.q.iter()
            .enumerate()
            .map(|(j, q)| format!("J{} {:.4}", j + 1, tidy(*q)))
            .collect::<Vec<_>>();
    outln!("  joints: {} rad", q.join(", "));
    let limits = table.limits();
    let outside: Vec<String> = (0..limits.len())
        .filter(|&j| s.q[j] < limits[j].0 || s.q[j] > limits[j].1)
        .map(|j| format!("J{}", j + 1))
        .collect();
    if !outside.is_empty() {
        outln!("  note: {} outside the joint-limit table", outside.join(", "));
    }
    Ok(())
}
