//! `hitl stub`: the MuJoCo stub of the arm on its own, speaking the xArm protocol on loopback
//! until Ctrl-C. Any xArm client (the official Python SDK, `hitl run --arm 127.0.0.1`) can
//! connect to it as to a control box.

use crate::exit;
use hitl_drivers::xarm::report::ReportKind;
use hitl_sim_stub::mujoco_plant::MujocoPlant;
use hitl_sim_stub::{Fault, Stub, StubConfig, StubHandle};
use hitl_trajectories::lab::LabConfig;
use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::mpsc;

/// Serve the stub standalone.
#[derive(Debug, clap::Args)]
pub struct StubArgs {
    /// Address to listen on. Loopback by default; anything else needs --allow-remote.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Command port (a control box's is 502; binding it needs root or CAP_NET_BIND_SERVICE).
    #[arg(long, value_name = "P", default_value_t = 502)]
    pub cmd_port: u16,
    /// Port of the real report (a box's 30003, 100 Hz). The other report ports follow the box's
    /// layout below it: P-3 real-time (30000, 200 Hz), P-2 normal (30001, 5 Hz), P-1 rich
    /// (30002, 5 Hz).
    #[arg(long, value_name = "P", default_value_t = 30003, value_parser = clap::value_parser!(u16).range(3..))]
    pub report_port: u16,
    /// MJCF scene to load instead of the one generated from the lab configuration.
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// Lab configuration (TOML); without it, the built-in DreamSat-Bench lab.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Inject a fault, `KIND[:VALUE]@SECONDS` after start (drop-connection, stall-reports,
    /// stall-replies, arm-error, deviation, estop, door-open). Repeatable.
    #[arg(long = "fault", value_name = "KIND@SECONDS")]
    pub faults: Vec<Fault>,
    /// Allow a non-loopback --bind (the stub then answers anyone on that network).
    #[arg(long)]
    pub allow_remote: bool,
    /// Arm serial number the stub answers with; it picks the joint-limit table the stub
    /// enforces, as on a real arm (digits 3-6 in 1305..8499: a current xArm7, else the first
    /// arms' wider table). Default: a current xArm7.
    #[arg(long, value_name = "SN", default_value = hitl_sim_stub::server::arm_box::DEFAULT_ARM_SN)]
    pub serial: String,
    /// Firmware version the stub answers with, vMAJOR.MINOR.PATCH (error 60, the servo_j TCP
    /// speed limit, exists from v2.3.0 on).
    #[arg(long, value_name = "vX.Y.Z", default_value = hitl_sim_stub::server::arm_box::DEFAULT_FIRMWARE)]
    pub firmware: String,
}

fn report_ports(real: u16) -> Vec<(ReportKind, u16)> {
    vec![
        (ReportKind::RealTime, real - 3),
        (ReportKind::Normal, real - 2),
        (ReportKind::Rich, real - 1),
        (ReportKind::Real, real),
    ]
}

fn start(args: &StubArgs) -> Result<StubHandle, (u8, String)> {
    if !args.bind.is_loopback() && !args.allow_remote {
        return Err((
            exit::BAD_INPUT,
            format!("refusing to bind {}: not loopback (add --allow-remote to mean it)", args.bind),
        ));
    }
    let lab = match &args.config {
        Some(path) => LabConfig::load(path).map_err(|e| (exit::BAD_INPUT, e.to_string()))?,
        None => LabConfig::default(),
    };
    let plant = MujocoPlant::new(&lab, args.scene.as_deref())
        .map_err(|e| (exit::BAD_INPUT, e.to_string()))?;
    let mut config = StubConfig {
        bind: args.bind,
        allow_remote: args.allow_remote,
        cmd_port: args.cmd_port,
        report_ports: report_ports(args.report_port),
        faults: args.faults.clone(),
        ..StubConfig::default()
    }
    .with_serial(&args.serial);
    config.identity.firmware = args.firmware.clone();
    config.identity.validate().map_err(|e| (exit::BAD_INPUT, e.to_string()))?;
    Stub::start(config, Box::new(plant)).map_err(|e| (exit::DEVICE, e.to_string()))
}

pub fn run(args: StubArgs) -> u8 {
    let stub = match start(&args) {
        Ok(s) => s,
        Err((code, msg)) => {
            crate::errln!("hitl stub: {msg}");
            return code;
        }
    };
    let (sn, table, limits) = stub.with_box(|b| {
        let sn = b.identity_config().arm_sn.clone();
        let table = hitl_trajectories::joint_table::JointTable::for_serial(&sn);
        (sn, table, b.joint_limits())
    });
    crate::errln!(
        "hitl stub: xArm7 {sn}, firmware {}, joint table {table} (J2 {:.6}..{:.6}, J4 {:.6}..{:.6} rad)",
        args.firmware,
        limits[1].0,
        limits[1].1,
        limits[3].0,
        limits[3].1
    );
    crate::errln!("hitl stub: xArm command port on {}", stub.cmd_addr());
    for kind in ReportKind::ALL {
        if let Some(a) = stub.report_addr(kind) {
            crate::errln!("hitl stub: report {:?} ({} Hz) on {a}", kind, kind.rate_hz());
        }
    }
    for f in &args.faults {
        crate::errln!("hitl stub: fault scheduled: {f}");
    }
    crate::errln!("hitl stub: serving until Ctrl-C");
    let (tx, rx) = mpsc::channel();
    if let Err(e) = ctrlc::set_handler(move || {
        let _ = tx.send(());
    }) {
        crate::errln!("hitl stub: cannot install the Ctrl-C handler: {e}");
        return exit::DEVICE;
    }
    let _ = rx.recv();
    let phys = stub.physics();
    crate::errln!(
        "hitl stub: stopping after {:.1} s wall, {:.1} s simulated ({} late steps)",
        phys.wall_s,
        phys.sim_s,
        phys.late_steps
    );
    let c = stub.counters();
    let load = |a: &std::sync::atomic::AtomicU64| a.load(std::sync::atomic::Ordering::Relaxed);
    crate::errln!(
        "hitl stub: {} commands at most 250 per second, {} of them waited for their slot (longest {:.2} ms)",
        load(&c.commands),
        load(&c.paced_commands),
        load(&c.max_pace_wait_ns) as f64 * 1e-6
    );
    stub.shutdown();
    exit::OK
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_ports_follow_the_box_layout() {
        let p = report_ports(30003);
        assert_eq!(
            p,
            vec![
                (ReportKind::RealTime, 30000),
                (ReportKind::Normal, 30001),
                (ReportKind::Rich, 30002),
                (ReportKind::Real, 30003)
            ]
        );
    }
}
