//! The stub's xArm protocol server: a command port, the report ports, and a real-time thread
//! that steps the plant, all around one [`ArmBox`] state machine.
//!
//! - [`arm_box`]: the control box's state machine over the plant;
//! - [`command`]: the command port (502): private Modbus-TCP requests and replies;
//! - [`reports`]: the report ports (30000-30003) at a real box's rates;
//! - [`stepper`]: the physics thread (fixed step against absolute deadlines) and fault schedule;
//! - [`bench`]: protocol benchmarks against a running stub.
//!
//! Threads share one [`Shared`] value: the box behind a mutex (held for one request or one physics
//! step at a time), flags and counters as atomics.

pub mod arm_box;
pub mod bench;
pub mod command;
pub mod reports;
pub mod stepper;

use crate::faults::{Fault, FaultKind, SimInputs, SimInputsReader};
use crate::plant::Plant;
use arm_box::{ArmBox, BoxStatus};
use hitl_drivers::xarm::report::ReportKind;
use hitl_hal::Joints;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Why the stub could not start.
#[derive(Debug, thiserror::Error)]
pub enum StubError {
    #[error("refusing to serve the arm protocol on non-loopback address {0} (pass --allow-remote to mean it)")]
    NotLoopback(IpAddr),
    #[error("cannot listen on {addr} ({what}): {source}")]
    Bind { addr: SocketAddr, what: &'static str, source: std::io::Error },
    #[error("stub: {0}")]
    Io(#[from] std::io::Error),
}

/// How to run the stub.
#[derive(Debug, Clone)]
pub struct StubConfig {
    /// Address to listen on (loopback unless `allow_remote`).
    pub bind: IpAddr,
    pub allow_remote: bool,
    /// Command port (the box's is 502; 0 = any free port).
    pub cmd_port: u16,
    /// Report ports to serve (0 = any free port).
    pub report_ports: Vec<(ReportKind, u16)>,
    /// Faults to inject, seconds after start.
    pub faults: Vec<Fault>,
    /// The arm's pose at power-up.
    pub initial_q: Joints,
    /// Joint limits the box enforces on servo_j and move_joint targets.
    pub joint_limits: [(f64, f64); 7],
    /// Physics step, seconds.
    pub physics_dt: f64,
}

impl Default for StubConfig {
    fn default() -> Self {
        Self {
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            allow_remote: false,
            cmd_port: hitl_drivers::xarm::COMMAND_PORT,
            report_ports: ReportKind::ALL.iter().map(|k| (*k, k.default_port())).collect(),
            faults: Vec::new(),
            initial_q: [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0],
            joint_limits: hitl_trajectories::kinematics::JOINT_LIMITS,
            physics_dt: 0.002,
        }
    }
}

impl StubConfig {
    /// The default stub on loopback with every port chosen by the OS (for tests and the
    /// embedded stub of `hitl run`).
    pub fn ephemeral() -> Self {
        Self {
            cmd_port: 0,
            report_ports: ReportKind::ALL.iter().map(|k| (*k, 0)).collect(),
            ..Self::default()
        }
    }
}

/// Counters of a running stub.
#[derive(Debug, Default)]
pub struct Counters {
    pub steps: AtomicU64,
    /// Physics steps that started more than one step late (the thread fell behind).
    pub late_steps: AtomicU64,
    /// Nanoseconds spent inside physics steps (lock held).
    pub step_busy_ns: AtomicU64,
    pub connections: AtomicU64,
    pub reports_sent: AtomicU64,
    pub bad_frames: AtomicU64,
}

/// State shared by the stub's threads.
pub struct Shared {
    pub arm: Mutex<ArmBox>,
    pub inputs: Arc<SimInputs>,
    pub stop: AtomicBool,
    /// Bumped by a drop-connection fault: connections opened before it close.
    pub drop_epoch: AtomicU64,
    /// Reports are stalled until this many ns after start (u64::MAX: for good; 0: not stalled).
    pub stall_until_ns: AtomicU64,
    /// The command port reads and answers nothing until this many ns after start (like
    /// `stall_until_ns`); the connection stays open.
    pub stall_replies_until_ns: AtomicU64,
    pub started: Instant,
    pub counters: Counters,
    pub physics_dt: f64,
}

impl Shared {
    pub fn lock_arm(&self) -> MutexGuard<'_, ArmBox> {
        // A panic while holding the lock leaves the box usable: recover the guard.
        self.arm.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn elapsed_ns(&self) -> u64 {
        u64::try_from(self.started.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    pub fn stopping(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }

    /// The end of a stall lasting `seconds` from now (`None`: until the stub stops).
    fn until(&self, seconds: Option<f64>) -> u64 {
        match seconds {
            Some(s) => self.elapsed_ns().saturating_add((s * 1e9) as u64),
            None => u64::MAX,
        }
    }

    /// Whether the command port is stalled now.
    pub fn replies_stalled(&self) -> bool {
        self.stall_replies_until_ns.load(Ordering::SeqCst) > self.elapsed_ns()
    }

    /// Apply a fault now.
    pub fn apply(&self, kind: FaultKind) {
        match kind {
            FaultKind::DropConnection => {
                self.drop_epoch.fetch_add(1, Ordering::SeqCst);
            }
            FaultKind::StallReports(d) => {
                self.stall_until_ns.store(self.until(d), Ordering::SeqCst)
            }
            FaultKind::StallReplies(d) => {
                self.stall_replies_until_ns.store(self.until(d), Ordering::SeqCst)
            }
            FaultKind::ArmError(code) => self.lock_arm().raise_error(code),
            FaultKind::Deviation(rad) => self.lock_arm().set_deviation(rad),
            FaultKind::Estop => {
                self.inputs.set_estop(true);
                self.lock_arm().set_estop(true);
            }
            FaultKind::DoorOpen => self.inputs.set_door_open(true),
        }
    }
}

/// The stub: start it with [`Stub::start`].
pub struct Stub;

/// A running stub. Dropping it shuts it down.
pub struct StubHandle {
    shared: Arc<Shared>,
    cmd_addr: SocketAddr,
    report_addrs: Vec<(ReportKind, SocketAddr)>,
    threads: Vec<JoinHandle<()>>,
}

fn bind(addr: SocketAddr, what: &'static str) -> Result<TcpListener, StubError> {
    let l = TcpListener::bind(addr).map_err(|source| StubError::Bind { addr, what, source })?;
    l.set_nonblocking(true)?;
    Ok(l)
}

impl Stub {
    /// Bind every port, then start the physics, command and report threads.
    pub fn start(config: StubConfig, plant: Box<dyn Plant>) -> Result<StubHandle, StubError> {
        if !config.bind.is_loopback() && !config.allow_remote {
            return Err(StubError::NotLoopback(config.bind));
        }
        let cmd = bind(SocketAddr::new(config.bind, config.cmd_port), "command port")?;
        let mut report_listeners = Vec::new();
        for (kind, port) in &config.report_ports {
            let what = match kind {
                ReportKind::RealTime => "report port 30000",
                ReportKind::Normal => "report port 30001",
                ReportKind::Rich => "report port 30002",
                ReportKind::Real => "report port 30003",
            };
            report_listeners.push((*kind, bind(SocketAddr::new(config.bind, *port), what)?));
        }
        let shared = Arc::new(Shared {
            arm: Mutex::new(ArmBox::new(plant, config.initial_q, config.joint_limits)),
            inputs: Arc::new(SimInputs::default()),
            stop: AtomicBool::new(false),
            drop_epoch: AtomicU64::new(0),
            stall_until_ns: AtomicU64::new(0),
            stall_replies_until_ns: AtomicU64::new(0),
            started: Instant::now(),
            counters: Counters::default(),
            physics_dt: config.physics_dt,
        });
        let cmd_addr = cmd.local_addr()?;
        let mut report_addrs = Vec::new();
        let mut threads = Vec::new();
        let s = shared.clone();
        let faults = config.faults.clone();
        threads.push(spawn("hitl-stub-physics", move || stepper::run(s, faults))?);
        let s = shared.clone();
        threads.push(spawn("hitl-stub-cmd", move || command::serve(s, cmd))?);
        for (kind, l) in report_listeners {
            report_addrs.push((kind, l.local_addr()?));
            let s = shared.clone();
            threads.push(spawn("hitl-stub-report", move || reports::serve(s, l, kind))?);
        }
        Ok(StubHandle { shared, cmd_addr, report_addrs, threads })
    }
}

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> Result<JoinHandle<()>, StubError> {
    Ok(std::thread::Builder::new().name(name.into()).spawn(f)?)
}

/// Figures about the physics thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicsStats {
    pub steps: u64,
    pub late_steps: u64,
    /// Simulated seconds advanced.
    pub sim_s: f64,
    /// Wall seconds since start.
    pub wall_s: f64,
    /// Mean time one step takes, seconds (what bounds the achievable real-time factor).
    pub mean_step_s: f64,
}

impl StubHandle {
    pub fn cmd_addr(&self) -> SocketAddr {
        self.cmd_addr
    }

    /// Address of a report port, if served.
    pub fn report_addr(&self, kind: ReportKind) -> Option<SocketAddr> {
        self.report_addrs.iter().find(|(k, _)| *k == kind).map(|(_, a)| *a)
    }

    /// Where a [`ReportReader`](hitl_drivers::xarm::ReportReader) finds this stub's reports:
    /// `base` with its report port (30003's stand-in) and codes port (30001's) set to this
    /// stub's, and the host to connect to.
    pub fn report_config(
        &self,
        base: hitl_drivers::xarm::ReportConfig,
    ) -> (IpAddr, hitl_drivers::xarm::ReportConfig) {
        let port = |k| self.report_addr(k).map(|a| a.port());
        let config = hitl_drivers::xarm::ReportConfig {
            port: port(base.kind).or(base.port),
            codes_port: base.codes_port.and(port(ReportKind::Normal)),
            ..base
        };
        (self.cmd_addr.ip(), config)
    }

    /// The plant's true joints (no injected deviation).
    pub fn plant_joints(&self) -> Joints {
        self.shared.lock_arm().plant_joints()
    }

    /// The box's motors, state, mode and codes.
    pub fn status(&self) -> BoxStatus {
        self.shared.lock_arm().status()
    }

    /// Run `f` on the box (and through it the plant) with the physics paused for the call.
    pub fn with_box<R>(&self, f: impl FnOnce(&mut ArmBox) -> R) -> R {
        f(&mut self.shared.lock_arm())
    }

    /// The simulated safety inputs (e-stop, door) as a [`hitl_hal::Inputs`].
    pub fn inputs(&self) -> SimInputsReader {
        SimInputsReader(self.shared.inputs.clone())
    }

    /// Inject a fault now.
    pub fn inject(&self, kind: FaultKind) {
        self.shared.apply(kind);
    }

    pub fn counters(&self) -> &Counters {
        &self.shared.counters
    }

    pub fn physics(&self) -> PhysicsStats {
        let c = &self.shared.counters;
        let steps = c.steps.load(Ordering::Relaxed);
        let busy = c.step_busy_ns.load(Ordering::Relaxed) as f64 * 1e-9;
        PhysicsStats {
            steps,
            late_steps: c.late_steps.load(Ordering::Relaxed),
            sim_s: steps as f64 * self.shared.physics_dt,
            wall_s: self.shared.started.elapsed().as_secs_f64(),
            mean_step_s: if steps > 0 { busy / steps as f64 } else { 0.0 },
        }
    }

    /// Stop every thread and close every socket.
    pub fn shutdown(mut self) {
        self.stop_threads();
    }

    fn stop_threads(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

impl Drop for StubHandle {
    fn drop(&mut self) {
        self.stop_threads();
    }
}

/// How often blocked threads look at the stop flag.
pub(crate) const POLL: Duration = Duration::from_millis(20);
