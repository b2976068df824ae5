//! A run from start to exit code: load and preflight, connect, open devices, enable, plan and
//! check the approach, play on the real-time thread, settle, stop, close. Everything that
//! allocates or blocks happens here, before or after the loop; the loop itself is [`super::tick`].

use super::interlocks::{Interlocks, Thresholds};
use super::motion::{plan_move, MoveLimits};
use super::setpoint::Setpoint;
use super::stop::StopPlanner;
use super::telemetry::{LoopStatus, NoTelemetry};
use super::tick::{ControlLoop, Devices, Health, LoopIo, Outcome, Program};
use crate::devices::inputs::RunInputs;
use crate::devices::none::{NoCamera, NoInputs, NoLight};
use crate::exit;
use crate::rt::{self, slot::LatestSlot, RtOptions};
use hitl_drivers::xarm::{ClientConfig, ReportConfig, ReportKind, ReportReader, XarmClient};
use hitl_hal::{Arm, ArmReports, ArmState, Joints, MonotonicClock};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::SetpointTable;
use hitl_trajectories::{npz, preflight, Trajectory};
use std::net::{IpAddr, SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Which arm the run drives.
#[derive(Debug, Clone)]
pub enum ArmTarget {
    /// The embedded MuJoCo stub on loopback, with faults to inject (`KIND@SECONDS`).
    Stub { faults: Vec<String> },
    /// A real xArm control box.
    Remote { host: String },
}

/// Everything `hitl run` was asked.
#[derive(Debug, Clone)]
pub struct RunRequest {
    pub trajectory: PathBuf,
    pub lab: LabConfig,
    pub rate_hz: f64,
    pub speed_scale: f64,
    pub target: ArmTarget,
    pub record: Option<PathBuf>,
    pub camera: String,
    pub light: String,
    pub perception: String,
    pub rt: RtOptions,
    pub plain_progress: bool,
}

/// A run that could not start (nothing moved), or a device that failed before the loop.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0}")]
    BadInput(String),
    #[error("preflight refused the trajectory; nothing moved:\n{0}")]
    Refused(String),
    #[error("{0}")]
    Device(String),
}

impl RunError {
    pub fn exit_code(&self) -> u8 {
        match self {
            RunError::BadInput(_) => exit::BAD_INPUT,
            RunError::Refused(_) => exit::PREFLIGHT_REFUSED,
            RunError::Device(_) => exit::DEVICE,
        }
    }
}

/// How a run ended, for the operator and the tests.
#[derive(Debug, Clone)]
pub struct RunReport {
    pub outcome: Outcome,
    pub exit_code: u8,
    pub approach_ticks: usize,
    pub playback_ticks: usize,
    pub captures: u64,
    pub max_late_ns: u64,
    pub overruns: u64,
    pub rt: rt::RtReport,
    /// Where the stub's arm ended (stub runs only).
    pub stub_final_q: Option<Joints>,
    pub recording: Option<PathBuf>,
}

impl RunReport {
    pub fn summary(&self) -> String {
        let how = match self.outcome {
            Outcome::Completed { ticks, settled } => format!(
                "completed: {ticks} ticks ({} approach, {} playback), {}",
                self.approach_ticks,
                self.playback_ticks,
                if settled { "settled on the last waypoint" } else { "settle timed out" }
            ),
            Outcome::Tripped { trip, stopped } => format!(
                "stopped by {} at tick {}: {} ({})",
                trip.kind.name(),
                trip.tick,
                trip.kind.detail(),
                if stopped { "controlled stop completed" } else { "arm told to hold" }
            ),
        };
        let mut s = format!(
            "{how}\ncaptures {}, max wake lateness {:.1} us, overruns {}\nloop thread: {}",
            self.captures,
            self.max_late_ns as f64 / 1e3,
            self.overruns,
            self.rt.summary()
        );
        if let Some(path) = &self.recording {
            s.push_str(&format!("\nrecording: {}", path.display()));
        }
        s.push_str(&format!("\nexit code {}", self.exit_code));
        s
    }
}

/// The preflight's violations, one per line.
fn violations(report: &preflight::PreflightReport) -> String {
    let lines: Vec<String> =
        report.violations.iter().map(|v| format!("  - {}", v.message)).collect();
    lines.join("\n")
}

/// Load, time-parametrise and preflight the trajectory: refuse before anything is opened.
fn prepare(req: &RunRequest) -> Result<(Trajectory, SetpointTable), RunError> {
    let loaded = npz::load(&req.trajectory).map_err(|e| RunError::BadInput(e.to_string()))?;
    for warning in &loaded.warnings {
        eprintln!("warning: {warning}");
    }
    let traj = loaded.trajectory;
    let table = SetpointTable::build(&traj, req.rate_hz, req.speed_scale)
        .map_err(|e| RunError::BadInput(e.to_string()))?;
    let report = preflight::check(&traj, &table, &req.lab);
    if !report.is_safe() {
        return Err(RunError::Refused(violations(&report)));
    }
    Ok((traj, table))
}

/// A setpoint table for a planned move, so the approach goes through the same preflight rules.
fn approach_table(
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
    };
    (traj, table)
}

/// Plan the slow move from the arm's pose to the first waypoint and check it like a trajectory.
fn plan_approach(
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
    let approach = plan_move(start, &table.q[0], &limits, table.dt)
        .map_err(|e| RunError::Refused(format!("approach: {e}")))?;
    if approach.is_empty() {
        return Ok(approach);
    }
    let (traj, approach_table) = approach_table(&approach, start, table.rate_hz);
    let report = preflight::check(&traj, &approach_table, lab);
    if !report.is_safe() {
        return Err(RunError::Refused(format!(
            "the approach from the arm's pose to the first waypoint is unsafe:\n{}",
            violations(&report)
        )));
    }
    Ok(approach)
}

fn resolve(host: &str, port: u16) -> Result<SocketAddr, RunError> {
    (host, port)
        .to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| RunError::BadInput(format!("cannot resolve arm address '{host}'")))
}

/// The report reader thread: reports into the latest-value slot until told to stop or the
/// stream fails (then the tick's watchdog trips).
fn spawn_report_reader(
    mut reader: ReportReader,
    slot: LatestSlot<ArmState>,
    stop: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new().name("hitl-reports".into()).spawn(move || {
        while !stop.load(Ordering::Acquire) {
            match reader.next_report() {
                Ok(state) => slot.publish(state),
                Err(_) if stop.load(Ordering::Acquire) => break,
                Err(_) => break,
            }
        }
    })
}

/// Wait for the first arm report (the arm is alive and we know where it is).
fn first_report(
    reader: &mut rt::slot::SlotReader<ArmState>,
    timeout: Duration,
) -> Option<ArmState> {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if let (Some(state), true) = reader.latest() {
            return Some(state);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    None
}

/// The embedded stub, when the run targets it.
#[cfg(feature = "stub")]
struct EmbeddedStub {
    handle: hitl_sim_stub::StubHandle,
}

#[cfg(feature = "stub")]
fn start_stub(faults: &[String], lab: &LabConfig) -> Result<EmbeddedStub, RunError> {
    use hitl_sim_stub::{mujoco_plant::MujocoPlant, Fault, Stub, StubConfig};
    let faults = faults
        .iter()
        .map(|s| s.parse::<Fault>().map_err(|e| RunError::BadInput(e.to_string())))
        .collect::<Result<Vec<_>, _>>()?;
    let plant = MujocoPlant::new(lab, None).map_err(|e| RunError::Device(format!("stub: {e}")))?;
    let config = StubConfig { faults, ..StubConfig::ephemeral() };
    let handle =
        Stub::start(config, Box::new(plant)).map_err(|e| RunError::Device(format!("stub: {e}")))?;
    Ok(EmbeddedStub { handle })
}

/// Play `req` and say how it ended.
pub fn run(req: RunRequest) -> Result<RunReport, RunError> {
    let (_traj, table) = prepare(&req)?;
    if req.camera != "none" && req.camera != "sim" {
        return Err(RunError::BadInput(format!(
            "--camera {}: not available in this build",
            req.camera
        )));
    }
    if req.light != "none" && req.light != "sim" {
        return Err(RunError::BadInput(format!(
            "--light {}: not available in this build",
            req.light
        )));
    }

    // The arm: the embedded stub, or the real box.
    #[cfg(feature = "stub")]
    let mut stub = None;
    let (cmd_addr, report_host) = match &req.target {
        #[cfg(feature = "stub")]
        ArmTarget::Stub { faults } => {
            let s = start_stub(faults, &req.lab)?;
            let addr = s.handle.cmd_addr();
            stub = Some(s);
            (addr, addr.ip())
        }
        #[cfg(not(feature = "stub"))]
        ArmTarget::Stub { .. } => {
            return Err(RunError::BadInput(
                "this build has no embedded stub: pass --arm HOST".into(),
            ))
        }
        ArmTarget::Remote { host } => {
            let addr = resolve(host, hitl_drivers::xarm::COMMAND_PORT)?;
            (addr, addr.ip())
        }
    };
    let port_of = |kind: ReportKind| -> u16 {
        #[cfg(feature = "stub")]
        if let Some(s) = &stub {
            return s.handle.report_addr(kind).map_or(kind.default_port(), |a| a.port());
        }
        kind.default_port()
    };
    let clock = MonotonicClock::new();
    let mut arm = XarmClient::connect(cmd_addr, ClientConfig::default())
        .map_err(|e| RunError::Device(format!("arm at {cmd_addr}: {e}")))?;
    let reader = connect_reports(
        report_host,
        port_of(ReportKind::Real),
        Some(port_of(ReportKind::Normal)),
        clock,
    )?;
    let (slot, mut reports) = LatestSlot::new();
    let reader_stop = Arc::new(AtomicBool::new(false));
    let reader_thread = spawn_report_reader(reader, slot, Arc::clone(&reader_stop))
        .map_err(|e| RunError::Device(format!("report reader thread: {e}")))?;
    let first = first_report(&mut reports, Duration::from_secs(2))
        .ok_or_else(|| RunError::Device("the arm sent no report within 2 s".into()))?;

    arm.enable_servo().map_err(|e| RunError::Device(format!("enabling the arm: {e}")))?;
    let approach = plan_approach(&first.q, &table, &req.lab)?;
    let program = Program {
        playback: (0..table.ticks())
            .map(|k| Setpoint { q: table.q[k], qd: table.qd[k], qdd: table.qdd[k] })
            .collect(),
        capture: {
            let mut flags = vec![false; table.ticks()];
            for c in &table.captures {
                flags[c.tick] = true;
            }
            flags
        },
        light: table.light.clone().unwrap_or_default(),
        light_lead_ticks: 0,
        settle_tolerance_rad: 0.002,
        settle_max_ticks: (2.0 * table.rate_hz) as u64,
        approach,
    };

    let health = Health::default();
    let status = Arc::new(LoopStatus::default());
    let limits = &req.lab.limits;
    let stop_limits = MoveLimits {
        velocity: limits.velocity_rad_s,
        acceleration: limits.acceleration_rad_s2,
        jerk: limits.jerk_rad_s3,
    };
    let (planner, stop) = StopPlanner::start(stop_limits, table.dt, 10.0)
        .map_err(|e| RunError::Device(format!("stop planner thread: {e}")))?;
    let interlocks = Interlocks::new(Thresholds::from_lab(&req.lab));
    install_ctrlc(&health);

    #[cfg(feature = "stub")]
    let inputs = match &stub {
        Some(s) => RunInputs::Sim(s.handle.inputs()),
        None => RunInputs::None(NoInputs),
    };
    #[cfg(not(feature = "stub"))]
    let inputs = RunInputs::None(NoInputs);
    let io = LoopIo {
        reports,
        telemetry: NoTelemetry,
        status: Arc::clone(&status),
        health,
        stop,
        clock,
    };
    let rt_options = req.rt;
    let rate = table.rate_hz;
    let start_q = first.q;
    let (outcome, rt_report) = std::thread::scope(|scope| {
        let program = &program;
        let rt_thread = std::thread::Builder::new()
            .name("hitl-rt".into())
            .spawn_scoped(scope, move || {
                let rt_report = rt::os::apply(&rt_options);
                let devices = Devices { arm, camera: NoCamera, light: NoLight, inputs };
                let control = ControlLoop::new(program, devices, io, interlocks, rate, &start_q);
                let (outcome, mut devices) = control.run(rt_options.spin);
                let _ = devices.arm.flush_servo_replies();
                (outcome, rt_report)
            })
            .map_err(|e| RunError::Device(format!("real-time thread: {e}")))?;
        super::progress::follow(&status, program, req.plain_progress);
        rt_thread.join().map_err(|_| RunError::Device("the real-time thread panicked".into()))
    })?;
    drop(planner);
    reader_stop.store(true, Ordering::Release);
    let _ = reader_thread.join();

    #[cfg(feature = "stub")]
    let stub_final_q = stub.map(|s| {
        let q = s.handle.plant_joints();
        s.handle.shutdown();
        q
    });
    #[cfg(not(feature = "stub"))]
    let stub_final_q = None;

    let exit_code = match outcome {
        Outcome::Completed { .. } => exit::OK,
        Outcome::Tripped { trip, .. } => trip.kind.exit_code(),
    };
    for line in &rt_report.fallbacks {
        eprintln!("note: {line}");
    }
    Ok(RunReport {
        outcome,
        exit_code,
        approach_ticks: program.approach.len(),
        playback_ticks: program.playback.len(),
        captures: status.captures.load(Ordering::Relaxed),
        max_late_ns: status.max_late_ns.load(Ordering::Relaxed),
        overruns: status.overruns.load(Ordering::Relaxed),
        rt: rt_report,
        stub_final_q,
        recording: req.record.clone(),
    })
}

fn connect_reports(
    host: IpAddr,
    port: u16,
    codes_port: Option<u16>,
    clock: MonotonicClock,
) -> Result<ReportReader, RunError> {
    let config = ReportConfig { port: Some(port), codes_port, clock, ..ReportConfig::default() };
    ReportReader::connect(host, config)
        .map_err(|e| RunError::Device(format!("arm report stream at {host}:{port}: {e}")))
}

/// Ctrl-C asks for a controlled stop; a second Ctrl-C is left to the default (ends the process).
fn install_ctrlc(health: &Health) {
    let flag = Arc::clone(&health.operator_stop);
    let _ = ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::AcqRel) {
            std::process::exit(i32::from(exit::OPERATOR_STOP));
        }
    });
}
