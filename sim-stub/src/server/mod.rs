//! The stub's xArm protocol server: a command port, the report ports, and a real-time thread
//! that steps the plant, all around one [`ArmBox`] state machine.
//!
//! - [`arm_box`]: the control box's state machine over the plant;
//! - [`command`]: the command port (502): private Modbus-TCP requests and replies;
//! - [`reports`]: the report ports (30000-30003) at a real box's rates;
//! - [`stepper`]: the physics thread (fixed step against absolute deadlines) and fault schedule;
//! - [`sim_clock`]: the same box on a simulated clock, advanced by the host instead of threads;
//! - [`bench`]: protocol benchmarks against a running stub.
//!
//! Threads share one [`Shared`] value: the box behind a mutex (held for one request or one physics
//! step at a time), flags and counters as atomics, and the command pacer that holds the box to
//! the rate a control box receives commands at (250 per second).

pub mod arm_box;
pub mod bench;
pub mod command;
pub mod reports;
pub mod sim_clock;
pub mod stepper;

use crate::faults::{Fault, FaultKind, SimInputs, SimInputsReader};
use crate::plant::Plant;
use arm_box::{ArmBox, BoxIdentityConfig, BoxStatus, IdentityError};
use hitl_drivers::xarm::report::ReportKind;
use hitl_hal::{Joints, DOF};
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
    Identity(#[from] IdentityError),
    #[error("stub: command rate {0} per second must be a positive number")]
    CommandRate(f64),
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
    /// Serial numbers and firmware the box answers with (a current xArm7 by default).
    pub identity: BoxIdentityConfig,
    /// Joint limits the box enforces on servo_j and move_joint targets; `None`: the table of
    /// the arm `identity` names (as the firmware and the official SDK pick it).
    pub joint_limits: Option<[(f64, f64); DOF]>,
    /// Commands the command port handles per second at most, over all connections (a box
    /// receives at most 250); `None` only for benchmarks of the client itself.
    pub max_command_rate_hz: Option<f64>,
    /// Physics step, seconds.
    pub physics_dt: f64,
    /// Runs first on every thread the stub starts (physics, accept loops, connections).
    pub thread_start: ThreadStart,
    /// On a simulated clock: no physics thread, no report pacing; the host advances the box
    /// with [`StubHandle::advance_to`] ([`sim_clock`]). Commands are not paced either.
    pub simulated: bool,
}

/// What every thread of the stub runs first. A control box has CPUs of its own; a stub embedded
/// in the controller's process shares them with rendering, perception and recording, so the host
/// gives the box's threads their priority here (`hitl run` puts them on SCHED_FIFO just below its
/// loop and report reader). None by default: the stub's threads stay on the normal scheduler.
#[derive(Clone, Default)]
pub struct ThreadStart(Option<Arc<dyn Fn() + Send + Sync>>);

impl ThreadStart {
    /// Run `f` at the start of every stub thread.
    pub fn new(f: impl Fn() + Send + Sync + 'static) -> Self {
        Self(Some(Arc::new(f)))
    }

    /// Start a named thread that runs the hook, then `f`.
    pub(crate) fn spawn(
        &self,
        name: &str,
        f: impl FnOnce() + Send + 'static,
    ) -> std::io::Result<JoinHandle<()>> {
        let hook = self.0.clone();
        std::thread::Builder::new().name(name.into()).spawn(move || {
            if let Some(hook) = hook {
                hook();
            }
            f()
        })
    }
}

impl std::fmt::Debug for ThreadStart {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() { "ThreadStart(hook)" } else { "ThreadStart(none)" })
    }
}

/// The rate a control box receives commands at, at most (UFACTORY: 250 Hz).
pub const BOX_COMMAND_RATE_HZ: f64 = 250.0;

impl Default for StubConfig {
    fn default() -> Self {
        Self {
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            allow_remote: false,
            cmd_port: hitl_drivers::xarm::COMMAND_PORT,
            report_ports: ReportKind::ALL.iter().map(|k| (*k, k.default_port())).collect(),
            faults: Vec::new(),
            initial_q: [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0],
            identity: BoxIdentityConfig::default(),
            joint_limits: None,
            max_command_rate_hz: Some(BOX_COMMAND_RATE_HZ),
            physics_dt: 0.002,
            thread_start: ThreadStart::default(),
            simulated: false,
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

    /// Answer as the arm with serial number `arm_sn` (the control box's number follows it).
    pub fn with_serial(mut self, arm_sn: &str) -> Self {
        self.identity.arm_sn = arm_sn.to_string();
        if let Some(rest) = arm_sn.get(2..) {
            self.identity.box_sn = format!("XX{rest}");
        }
        self
    }

    /// The joint limits the box enforces: the configured ones, else the serial number's table.
    pub fn effective_joint_limits(&self) -> [(f64, f64); DOF] {
        self.joint_limits.unwrap_or_else(|| {
            hitl_trajectories::joint_table::JointTable::for_serial(&self.identity.arm_sn).limits()
        })
    }
}

/// Spaces command handling at least one period apart over all connections, against absolute
/// slots (sleep overshoot does not accumulate): requests that arrive faster wait in the socket.
#[derive(Debug)]
pub struct CommandPacer {
    period_ns: u64,
    /// The slot the last command was handled in, ns after start (`u64::MAX`: never).
    last_slot_ns: Mutex<u64>,
}

impl CommandPacer {
    fn new(rate_hz: Option<f64>) -> Self {
        let period_ns = rate_hz.map(|r| (1e9 / r).round() as u64).unwrap_or(0);
        Self { period_ns, last_slot_ns: Mutex::new(u64::MAX) }
    }

    /// Reserve the next slot at or after `now_ns`; returns it.
    fn reserve(&self, now_ns: u64) -> u64 {
        let mut last = self.last_slot_ns.lock().unwrap_or_else(|e| e.into_inner());
        let slot = match *last {
            u64::MAX => now_ns,
            l => now_ns.max(l.saturating_add(self.period_ns)),
        };
        *last = slot;
        slot
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
    /// Command frames handled on the command port.
    pub commands: AtomicU64,
    /// Of those, the ones that waited for their slot (they came faster than 250 per second).
    pub paced_commands: AtomicU64,
    /// The longest wait for a slot, ns (how far behind a stream fell).
    pub max_pace_wait_ns: AtomicU64,
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
    pub pacer: CommandPacer,
    pub thread_start: ThreadStart,
    /// The simulated clock's state, when the stub runs on one.
    pub sim: Option<sim_clock::SimState>,
}

impl Shared {
    pub fn lock_arm(&self) -> MutexGuard<'_, ArmBox> {
        // A panic while holding the lock leaves the box usable: recover the guard.
        self.arm.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The box's time, ns since start: wall time, or on a simulated clock the simulated time.
    pub fn elapsed_ns(&self) -> u64 {
        match &self.sim {
            Some(sim) => sim.now_ns.load(Ordering::Acquire),
            None => u64::try_from(self.started.elapsed().as_nanos()).unwrap_or(u64::MAX),
        }
    }

    /// Wait for this command's slot (no faster than a box handles commands); returns the time
    /// it is handled at, seconds after start.
    pub fn pace_command(&self) -> f64 {
        let now = self.elapsed_ns();
        let c = &self.counters;
        c.commands.fetch_add(1, Ordering::Relaxed);
        if self.pacer.period_ns == 0 || self.sim.is_some() {
            return now as f64 * 1e-9;
        }
        let slot = self.pacer.reserve(now);
        if slot > now {
            c.paced_commands.fetch_add(1, Ordering::Relaxed);
            c.max_pace_wait_ns.fetch_max(slot - now, Ordering::Relaxed);
        }
        loop {
            let now = self.elapsed_ns();
            if now >= slot {
                break;
            }
            std::thread::sleep(Duration::from_nanos(slot - now));
        }
        slot as f64 * 1e-9
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
    /// On a simulated clock: what advances the box.
    driver: Option<Mutex<sim_clock::SimDriver>>,
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
        config.identity.validate()?;
        if let Some(r) = config.max_command_rate_hz {
            if !(r.is_finite() && r > 0.0) {
                return Err(StubError::CommandRate(r));
            }
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
            arm: Mutex::new(ArmBox::new(
                plant,
                config.initial_q,
                config.effective_joint_limits(),
                config.identity.clone(),
            )),
            inputs: Arc::new(SimInputs::default()),
            stop: AtomicBool::new(false),
            drop_epoch: AtomicU64::new(0),
            stall_until_ns: AtomicU64::new(0),
            stall_replies_until_ns: AtomicU64::new(0),
            started: Instant::now(),
            counters: Counters::default(),
            physics_dt: config.physics_dt,
            pacer: CommandPacer::new(config.max_command_rate_hz),
            thread_start: config.thread_start.clone(),
            sim: config.simulated.then(sim_clock::SimState::new),
        });
        let cmd_addr = cmd.local_addr()?;
        let mut report_addrs = Vec::new();
        let mut threads = Vec::new();
        let s = shared.clone();
        let faults = config.faults.clone();
        let start = &config.thread_start;
        let driver = if config.simulated {
            Some(Mutex::new(sim_clock::SimDriver::new(faults)))
        } else {
            threads.push(start.spawn("hitl-stub-physics", move || stepper::run(s, faults))?);
            None
        };
        let s = shared.clone();
        threads.push(start.spawn("hitl-stub-cmd", move || command::serve(s, cmd))?);
        for (kind, l) in report_listeners {
            report_addrs.push((kind, l.local_addr()?));
            let s = shared.clone();
            threads.push(start.spawn("hitl-stub-report", move || reports::serve(s, l, kind))?);
        }
        Ok(StubHandle { shared, cmd_addr, report_addrs, threads, driver })
    }
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

    /// On a simulated clock: step the box to `t_ns` of simulated time (faults, reports and
    /// physics due by then); does nothing on the wall clock.
    pub fn advance_to(&self, t_ns: u64) {
        if let (Some(driver), Some(sim)) = (&self.driver, &self.shared.sim) {
            driver.lock().unwrap_or_else(|e| e.into_inner()).advance_to(&self.shared, sim, t_ns);
        }
    }

    /// On a simulated clock, its state (counters the host waits on); `None` on the wall clock.
    pub fn sim(&self) -> Option<&sim_clock::SimState> {
        self.shared.sim.as_ref()
    }

    /// Whether the command port is stalled by a fault now.
    pub fn replies_stalled(&self) -> bool {
        self.shared.replies_stalled()
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
