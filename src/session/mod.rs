//! A run from start to exit code. [`run`] is [`preflight`] then [`PreflightedRun::play`], which
//! read top to bottom as the steps of a run: load and preflight; start the arm's side (the embedded stub); open and start the devices; start the
//! capture path (recorder, perception, frame intake); connect the arm, identify it, enable it;
//! plan the approach and the retreat around the lab's obstacles; play on the real-time thread
//! (with `--closed-loop`, beside the closed loop's navigator, `crate::closed_loop`); stop the
//! devices; close the capture path and the recording. Everything that allocates or
//! blocks happens here, before or after the loop; the loop itself is [`crate::control::tick`], which
//! borrows the devices this module owns.
//!
//! - [`prepare`]: load (or take in memory, [`TrajectorySource`]), time-parametrise and preflight,
//!   once per run ([`preflight`], before [`PreflightedRun::play`]); plan the approach and the
//!   retreat, checked by the same rules;
//! - [`arm_link`]: the arm's address, identity, report reader, first report, the embedded stub;
//! - [`devices`]: the target scene, the recorder, late frames (the devices themselves are opened
//!   by `crate::devices`, which is the only place that names drivers);
//! - [`operator`]: what Ctrl-C does;
//! - [`progress`]: the operator's progress line, read from the loop's status atomics;
//! - [`sim_clock`]: `--clock sim`, the simulated world the loop advances in lockstep.
//!
//! The run owns one tokio runtime for its whole life: the serial drivers' I/O tasks and the
//! perception forwarder live on it, from opening until the devices are stopped after the loop.

mod arm_link;
mod devices;
mod operator;
mod prepare;
mod progress;
// Without the stub there is no simulated clock to run: its parts stay, unused, so the types the
// session names exist in both builds.
#[cfg_attr(not(feature = "stub"), allow(dead_code))]
mod sim_clock;

pub use sim_clock::{ClockChoice, SimStats};

use crate::capture::intake::{Intake, IntakeMask, IntakeOutputs, IntakeStats};
use crate::capture::mask::{MaskDrawer, MaskSource};
use crate::capture::sink::{IntakeQueues, RunTelemetry};
use crate::capture::truth::LabFrames;
use crate::closed_loop::corridor::Corridor;
use crate::closed_loop::lockstep::{EstimateFlow, NavigatorTurns, TurnTaker};
use crate::closed_loop::navigator::{Navigator, NavigatorInputs, NavigatorSummary};
use crate::closed_loop::segment::PlanTicks;
use crate::closed_loop::{ClosedLoopConfig, PlanFrame};
use crate::control::correction::{CorrectionQueues, CorrectionStage};
use crate::control::interlocks::{Interlocks, Thresholds};
use crate::control::motion::MoveLimits;
use crate::control::planned_move::PlannedMove;
use crate::control::stop::StopPlanner;
use crate::control::stop_supervisor::StopConfirmation;
use crate::control::tick::{ControlLoop, Devices, Health, LoopIo, Outcome, Program};
use crate::devices::arm::{ClientConfig, ReportKind, RunArm, ServoReplies, COMMAND_PORT};
#[cfg(feature = "stub")]
use crate::devices::stub::{start_stub, EmbeddedStub};
use crate::devices::{self as run_devices, CameraSpec, DeviceChoice, DeviceError, RunDevices};
use crate::devices::{LightSpec, TriggerSpec};
use crate::exit;
use crate::rt::{self, slot::LatestSlot, slot::SlotReader, RtOptions};
use crate::telemetry::LoopStatus;
use arm_link::{connect_reports, first_report, resolve, spawn_report_reader};
use devices::{collect_late_frames, start_live, start_recorder, target_scene, TargetScene};
use hitl_hal::JointState;
use hitl_hal::{Arm, ArmState, Joints, MonotonicClock, SimTime};
use hitl_perception::{backend_from_spec, spawn_worker, BackendSpec, PoseResult, ReregisterPolicy};
use hitl_record::{
    ChunkCompression, EventKind, PoseStamped, RecorderHandle, SafetyEventMsg, Telemetry,
};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::SetpointTable;
use hitl_trajectories::Trajectory;
use operator::install_ctrlc;
use prepare::{plan_move_between, prepare, Prepared, Provenance};
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// A `--stub-fault KIND[:VALUE]@SECONDS`, parsed.
#[cfg(feature = "stub")]
pub use crate::devices::stub::StubFault;

/// A `--stub-fault` in a build without the embedded stub: never parses.
#[cfg(not(feature = "stub"))]
#[derive(Debug, Clone, PartialEq)]
pub struct StubFault(std::convert::Infallible);

#[cfg(not(feature = "stub"))]
impl std::str::FromStr for StubFault {
    type Err = String;
    fn from_str(_: &str) -> Result<Self, String> {
        Err("this build has no embedded stub to inject faults into".into())
    }
}

#[cfg(not(feature = "stub"))]
impl std::fmt::Display for StubFault {
    fn fmt(&self, _: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {}
    }
}

/// Which arm the run drives.
#[derive(Debug, Clone)]
pub enum ArmTarget {
    /// The embedded MuJoCo stub on loopback, with faults to inject.
    Stub { faults: Vec<StubFault> },
    /// A real xArm control box.
    Remote { host: String },
}

/// What a run plays: a file, a trajectory already in memory, or (parking) nothing.
#[derive(Debug, Clone)]
pub enum TrajectorySource {
    /// An NPZ file, loaded and validated before anything opens (a bad file: exit 2 naming it).
    /// `waypoint_rate_hz`: waypoints per second of a file without `t` (`--waypoint-rate`).
    File { path: PathBuf, waypoint_rate_hz: Option<f64> },
    /// A trajectory its caller built (`hitl calibrate`'s views), validated as a file would be;
    /// `name` says what it is in the recording's metadata, where a file's path would stand.
    InMemory { trajectory: Box<Trajectory>, name: String },
    /// `hitl park`: no trajectory; the only motion is the retreat from wherever the arm stands to
    /// the rest pose.
    Park,
}

/// Everything `hitl run` was asked.
#[derive(Debug, Clone)]
pub struct RunRequest {
    pub trajectory: TrajectorySource,
    pub lab: LabConfig,
    pub rate_hz: f64,
    pub speed_scale: f64,
    pub target: ArmTarget,
    pub record: Option<PathBuf>,
    /// Chunk compression of the recording.
    pub record_compression: ChunkCompression,
    pub camera: CameraSpec,
    pub light: LightSpec,
    /// The device that fires the camera and feeds its e-stop and door (`--trigger`).
    pub trigger: TriggerSpec,
    pub perception: BackendSpec,
    /// When the perception backend re-registers beyond its first frame and a lost track.
    pub reregister: ReregisterPolicy,
    /// Where each capture's target mask comes from (`--mask`), and the rendered mask's margin.
    pub mask: MaskSource,
    pub mask_margin_px: u32,
    /// Simulated camera intrinsics preset (nfov, wfov, orbbec) and size.
    pub camera_preset: String,
    pub camera_size: Option<(u32, u32)>,
    /// Target model: a built-in name (asymmetric, one-plane, two-planes) or an OBJ/STL path.
    pub target_model: String,
    /// SITL: the lab the embedded stub simulates (`--stub-config`), when it is not the one the
    /// controller believes (`lab`): the truth a calibration must recover.
    pub stub_lab: Option<LabConfig>,
    /// How the simulated camera's depth is degraded (`--depth-model`).
    pub depth_model: crate::devices::SimDepthModel,
    pub rt: RtOptions,
    /// After a completed run, go back to the lab's rest pose (`[arm] rest_q`) along a planned,
    /// checked path (`--no-retreat`: false, the arm stays where the trajectory ends).
    pub retreat: bool,
    /// SITL: where the embedded stub's arm powers up (`--stub-start-q`), e.g. where a previous
    /// run left a real arm; `None`: the stub's own power-up pose.
    pub stub_start_q: Option<Joints>,
    pub plain_progress: bool,
    /// Stream the run to Foxglove (`--live`; needs `record`: the recorder feeds it).
    pub live: Option<hitl_record::LiveConfig>,
    /// `--closed-loop` (with `--corridor-m`): correct the playback on the pose estimates
    /// (docs/closed-loop.md); `None`: open loop.
    pub closed_loop: Option<ClosedLoopConfig>,
    /// The host's clock, or simulated time in lockstep with the embedded stub (`--clock`).
    pub clock: ClockChoice,
}

impl RunRequest {
    /// `hitl park`: nothing to play but the retreat to the rest pose.
    fn parks(&self) -> bool {
        matches!(self.trajectory, TrajectorySource::Park)
    }
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

impl From<DeviceError> for RunError {
    fn from(e: DeviceError) -> Self {
        match e {
            DeviceError::BadInput(m) => RunError::BadInput(m),
            DeviceError::Failed(m) => RunError::Device(m),
        }
    }
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
    /// Ticks of the retreat to the rest pose (0: none planned).
    pub retreat_ticks: usize,
    pub captures: u64,
    pub max_late_ns: u64,
    pub overruns: u64,
    pub rt: rt::RtReport,
    /// Where the stub's arm ended (stub runs only).
    pub stub_final_q: Option<Joints>,
    pub recording: Option<PathBuf>,
    pub intake: IntakeStats,
    /// Pose estimates the perception worker returned.
    pub estimates: u64,
    /// Why the recording could not be closed properly, if so.
    pub record_error: Option<String>,
    /// Devices that failed during the run, each with its name and the driver's reason.
    pub device_faults: Vec<String>,
    /// After a trip: whether a report confirmed the box's stop (state 4).
    pub box_stop: Option<StopConfirmation>,
    /// What the live view did (`--live`).
    pub live: Option<hitl_record::LiveSummary>,
    /// What the closed loop did (`--closed-loop`).
    pub closed_loop: Option<NavigatorSummary>,
    /// On `--clock sim`: simulated and host time the loop took.
    pub sim: Option<SimStats>,
}

impl RunReport {
    pub fn summary(&self) -> String {
        let how = match self.outcome {
            Outcome::Completed { ticks, at_rest, .. }
                if self.approach_ticks + self.playback_ticks == 0 =>
            {
                format!(
                    "parked: {ticks} ticks ({} retreat), {}",
                    self.retreat_ticks,
                    match at_rest {
                        Some(true) => "back at the rest pose",
                        Some(false) => "the settle at the rest pose timed out",
                        None => "already at the rest pose",
                    }
                )
            }
            Outcome::Completed { ticks, settled, at_rest } => format!(
                "completed: {ticks} ticks ({} approach, {} playback{}), {}{}",
                self.approach_ticks,
                self.playback_ticks,
                if self.retreat_ticks > 0 {
                    format!(", {} retreat", self.retreat_ticks)
                } else {
                    String::new()
                },
                if settled { "settled on the last waypoint" } else { "settle timed out" },
                match at_rest {
                    None => "",
                    Some(true) => ", then back at the rest pose",
                    Some(false) => ", then retreated; the settle at the rest pose timed out",
                }
            ),
            Outcome::Tripped { trip, stopped } => format!(
                "stopped by {} at tick {}: {} ({}); the arm stays where it stopped: once the \
                 cause is cleared, `hitl park` takes it back to the rest pose along a planned path",
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
        if let Some(sim) = &self.sim {
            s.push_str(&format!("\n{}\n{}", sim.describe(), sim.describe_lockstep()));
        }
        if self.intake.frames > 0 {
            s.push_str(&format!("\n{}", self.intake.mask.describe()));
            s.push_str(&format!(
                "\nframes {} (recorded {}, not recorded {}, camera busy {}), sync error mean {:.2} ms max {:.2} ms, pose estimates {}",
                self.intake.frames,
                self.intake.recorded,
                self.intake.not_recorded,
                self.intake.captures_missed,
                self.intake.sync_error_mean_ns / 1e6,
                self.intake.sync_error_max_ns as f64 / 1e6,
                self.estimates
            ));
        }
        if let Some(l) = &self.live {
            s.push_str(&format!(
                "\nlive view ws://{}: {} viewer(s), {} messages sent ({} images), live dropped {}",
                l.addr, l.viewers, l.sent, l.images, l.dropped
            ));
        }
        if let Some(c) = &self.closed_loop {
            s.push_str(&format!("\n{}", c.describe()));
        }
        for fault in &self.device_faults {
            s.push_str(&format!("\ndevice fault: {fault}"));
        }
        if let Some(stop) = &self.box_stop {
            s.push_str(&format!("\n{}", stop.describe()));
        }
        if let Some(path) = &self.recording {
            s.push_str(&format!("\nrecording: {}", path.display()));
        }
        if let Some(e) = &self.record_error {
            s.push_str(&format!("\nrecording FAILED: {e}"));
        }
        s.push_str(&format!("\nexit code {}", self.exit_code));
        s
    }
}

/// Play `req` and say how it ended: [`preflight`], then [`PreflightedRun::play`].
pub fn run(req: RunRequest) -> Result<RunReport, RunError> {
    preflight(req)?.play()
}

/// A request whose trajectory is loaded, time-parametrised and preflighted (every rule over its
/// setpoints, captures against the camera's rate): what [`PreflightedRun::play`] plays. Made only
/// by [`preflight`], so a played trajectory is always one checked for its own request.
pub struct PreflightedRun {
    req: RunRequest,
    prepared: Prepared,
}

/// Step 1 of a run, before anything is opened: the clock choice, the trajectory (parking: the
/// rest pose alone) loaded, timed and preflighted; refused here, nothing has moved or opened.
/// `hitl calibrate` calls it apart from [`PreflightedRun::play`], to say a refusal in its own
/// words before the operator confirms a real arm.
pub fn preflight(req: RunRequest) -> Result<PreflightedRun, RunError> {
    check_clock_choice(&req)?;
    let prepared = if req.parks() { park_target(&req)? } else { prepare(&req)? };
    Ok(PreflightedRun { req, prepared })
}

impl PreflightedRun {
    /// The trajectory that will play.
    pub fn trajectory(&self) -> &Trajectory {
        &self.prepared.traj
    }

    /// Play the preflighted request and say how it ended. Each line is one step of the run.
    pub fn play(self) -> Result<RunReport, RunError> {
        let PreflightedRun { req, prepared } = self;
        play_prepared(req, prepared)
    }
}

/// The steps of a run after its preflight, top to bottom.
fn play_prepared(req: RunRequest, prepared: Prepared) -> Result<RunReport, RunError> {
    // Ctrl-C from the very start: during setup it stops the run at its first tick, with no motion.
    let operator_stop = Arc::new(AtomicBool::new(false));
    install_ctrlc(&operator_stop);
    let (traj, table) = (&prepared.traj, &prepared.table);

    // 1. Before anything is opened (the trajectory was preflighted): the target, the estimator
    // choice.
    let scene = target_scene(&req, traj)?;
    check_perception_choice(&req)?;
    let plan_frame = closed_loop_frame(&req, traj)?;
    let clock = match req.clock {
        ClockChoice::Realtime => MonotonicClock::new(),
        ClockChoice::Sim => MonotonicClock::simulated(SimTime::new()),
    };
    let runtime = io_runtime()?;

    // 2. The arm's side: the embedded stub, or the real box's address.
    let target = start_arm_target(&req, &scene, traj, table)?;

    // 3. Devices besides the arm, opened, configured and started before the arm is enabled.
    let mut devices = open_and_start_devices(&req, &target, runtime.handle(), clock.clone())?;

    // 4. The capture path: recorder, perception worker, frame intake.
    let capture = CapturePath::start(&req, &prepared, &scene, &runtime)?;

    // 5. The arm: connect, identify (its joint table, when tighter, checked against the joint
    // positions), read, enable.
    let mut link = connect_arm(&req, &target, traj, table, clock.clone())?;

    // 6. The program: the approach from where the arm stands, the trajectory, the retreat to rest;
    // each planned move is recorded with the run.
    let retreat_to = req.retreat.then_some(link.lab.arm.rest_q);
    let (program, moves) = if req.parks() {
        build_park_program(&link.first.q, table, &link.lab)?
    } else {
        build_program(&link.first.q, table, &link.lab, retreat_to.as_ref())?
    };
    let mut program = program;
    program.light_lead_ticks = light_lead_ticks(&req, table.rate_hz);
    for m in &moves {
        crate::errln!("{}", m.describe());
        if let Some(t) = &capture.record {
            t.push_metadata(&format!("{}_plan", m.name), m.metadata());
        }
    }
    #[cfg(feature = "stub")]
    if let Some(stub) = &target.stub {
        // The `orbit` Sun at a capture's loop tick: playback starts after the approach.
        stub.sun_track().set_playback_start(program.approach.len() as u64);
    }

    // 7. Play it on the real-time thread (the loop borrows the arm and the devices).
    let played = play(
        &req,
        &program,
        table,
        &mut link,
        &mut devices,
        &capture,
        operator_stop,
        &clock,
        &target,
        plan_frame,
    )?;

    // 7b. A tripped run: the box's stop repeated until a report shows it (off the loop thread;
    // on a simulated clock, each look at the reports moves the world on by one period).
    let mut after_loop = target.after_loop(&link, &capture, &clock, table.dt);
    let box_stop = arm_link::confirm_stop(
        &mut link.arm,
        &mut link.stop_reports,
        &played.outcome,
        &clock,
        capture.record.as_ref(),
        &mut after_loop,
    );
    drop(after_loop);

    // 8. After the loop: the report reader, the devices, the capture path, the stub.
    link.close();
    let device_faults = close_devices(&mut devices, &capture, played.captures);
    let closed = capture.close(&runtime, &played.outcome, &device_faults);
    #[cfg(feature = "stub")]
    let stub_final_q = target.close();
    #[cfg(not(feature = "stub"))]
    let stub_final_q = None;

    let mut report = report(&req, &program, played, closed, stub_final_q, device_faults);
    report.box_stop = box_stop;
    Ok(report)
}

/// `--clock sim` is only for the embedded stub: a real box keeps its own time, which no run can
/// simulate. Refused before anything is opened or connected.
fn check_clock_choice(req: &RunRequest) -> Result<(), RunError> {
    if req.clock != ClockChoice::Sim {
        return Ok(());
    }
    match &req.target {
        ArmTarget::Remote { host } => Err(RunError::BadInput(format!(
            "--clock sim runs on the embedded stub only; a real arm ({host}) keeps real time: \
             use --clock realtime with --arm"
        ))),
        ArmTarget::Stub { .. } if cfg!(not(feature = "stub")) => Err(RunError::BadInput(
            "--clock sim needs the embedded stub, which this build does not have".into(),
        )),
        ArmTarget::Stub { .. } => Ok(()),
    }
}

/// `--reregister-*` only make sense with a pose estimator; the simulator's mask only with the
/// simulated camera.
fn check_perception_choice(req: &RunRequest) -> Result<(), RunError> {
    if req.mask == MaskSource::Sim && req.camera != CameraSpec::Sim {
        return Err(RunError::BadInput(format!(
            "--mask sim needs --camera sim (only the simulated camera has a mask of its own); \
             with --camera {} use --mask rendered (drawn from the lab configuration) or none",
            req.camera
        )));
    }
    if req.perception == BackendSpec::None && req.reregister != ReregisterPolicy::default() {
        return Err(RunError::BadInput(
            "--reregister-every and --reregister-residual-m need a pose estimator \
             (--perception icp|mono|onnx:MODEL|socket:PATH)"
                .into(),
        ));
    }
    Ok(())
}

/// `--closed-loop`: the plan's relative frame (a planned trajectory), an estimator and a camera to
/// feed it; checked before anything opens (exit 2 otherwise).
fn closed_loop_frame(req: &RunRequest, traj: &Trajectory) -> Result<Option<PlanFrame>, RunError> {
    let Some(cfg) = &req.closed_loop else { return Ok(None) };
    if req.parks() {
        return Ok(None);
    }
    if req.perception == BackendSpec::None || req.camera == CameraSpec::None {
        return Err(RunError::BadInput(
            "--closed-loop needs a camera and a pose estimator (--camera sim|orbbec and \
             --perception icp|onnx:MODEL|socket:PATH): it corrects the plan on what they see"
                .into(),
        ));
    }
    Corridor::new(cfg.corridor_m).map_err(RunError::BadInput)?;
    PlanFrame::from_plan(traj, req.speed_scale).map(Some).map_err(RunError::BadInput)
}

/// The run's one tokio runtime, kept until the run returns: serial drivers' I/O tasks and the
/// perception forwarder live on it.
fn io_runtime() -> Result<tokio::runtime::Runtime, RunError> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("hitl-io")
        .enable_all()
        .build()
        .map_err(|e| RunError::Device(format!("async runtime: {e}")))
}

/// Where the arm is: the embedded stub (started here) or a real box.
struct ArmTargetLink {
    #[cfg(feature = "stub")]
    stub: Option<EmbeddedStub>,
    cmd_addr: SocketAddr,
    report_host: IpAddr,
}

impl ArmTargetLink {
    fn report_port(&self, kind: ReportKind) -> u16 {
        #[cfg(feature = "stub")]
        if let Some(s) = &self.stub {
            return s.report_addr(kind).map_or(kind.default_port(), |a| a.port());
        }
        kind.default_port()
    }

    /// Shut the stub down; where its arm ended.
    #[cfg(feature = "stub")]
    fn close(self) -> Option<Joints> {
        self.stub.map(EmbeddedStub::close)
    }

    /// The embedded stub, when it runs on the simulated clock.
    #[cfg(feature = "stub")]
    fn sim_stub(&self) -> Option<&EmbeddedStub> {
        self.stub.as_ref().filter(|s| s.sim().is_some())
    }

    /// Before the loop, on a simulated clock: write the reports due now (simulated time stands
    /// still until the loop starts). Nothing on the host's clock.
    fn prime(&self) {
        #[cfg(feature = "stub")]
        if let Some(stub) = self.sim_stub() {
            stub.advance_to(0);
        }
    }

    /// After the loop: what moves the world on by one period each time it is called (on a
    /// simulated clock; nothing on the host's, whose time moves by itself).
    fn after_loop<'a>(
        &'a self,
        link: &ArmLink,
        capture: &CapturePath,
        clock: &MonotonicClock,
        dt: f64,
    ) -> Box<dyn FnMut() + 'a> {
        #[cfg(feature = "stub")]
        if let (Some(stub), Some(time)) = (self.sim_stub(), clock.sim_time().cloned()) {
            let watched = link.watched(capture);
            let times = sim_clock::WorldTimes::default();
            let period_ns = (dt * 1e9).round() as u64;
            return Box::new(move || {
                let t = time.now_ns() + period_ns;
                time.advance_to(t);
                let mut world = sim_clock::SimWorld {
                    stub,
                    watched: &watched,
                    stop_planned: &|| true,
                    times: &times,
                };
                rt::World::advance_to(&mut world, t);
            });
        }
        let _ = (link, capture, clock, dt);
        Box::new(|| {})
    }
}

fn start_arm_target(
    req: &RunRequest,
    scene: &TargetScene,
    traj: &Trajectory,
    table: &SetpointTable,
) -> Result<ArmTargetLink, RunError> {
    match &req.target {
        #[cfg(feature = "stub")]
        ArmTarget::Stub { faults } => {
            // The scene as the lab configuration (or --scene-kind) says, its Earth along the
            // plan's nadir, its Sun following the trajectory's Sun phase.
            let look = hitl_sim_stub::mjcf::SceneOptions {
                kind: req.lab.scene.kind,
                rtn_to_base: hitl_trajectories::planner::rtn_to_base(traj)
                    .unwrap_or_else(hitl_trajectories::planner::mapping::default_rtn_to_base),
            };
            let stub = start_stub(
                faults,
                req.stub_lab.as_ref().unwrap_or(&req.lab),
                &scene.model,
                scene.scale,
                &look,
                req.rt.fifo_priority,
                req.stub_start_q,
                req.clock == ClockChoice::Sim,
            )?
            .with_depth_model(req.depth_model, 0);
            stub.sun_track()
                .set_schedule(&crate::capture::sim_light::sun_schedule(traj, table, &req.lab));
            let cmd_addr = stub.cmd_addr();
            Ok(ArmTargetLink { cmd_addr, report_host: cmd_addr.ip(), stub: Some(stub) })
        }
        #[cfg(not(feature = "stub"))]
        ArmTarget::Stub { .. } => {
            let _ = (scene, traj, table);
            Err(RunError::BadInput("this build has no embedded stub: pass --arm HOST".into()))
        }
        ArmTarget::Remote { host } => {
            let cmd_addr = resolve(host, COMMAND_PORT)?;
            Ok(ArmTargetLink {
                cmd_addr,
                report_host: cmd_addr.ip(),
                #[cfg(feature = "stub")]
                stub: None,
            })
        }
    }
}

/// Open camera, light, inputs and trigger lines as asked, configure and arm the camera, and start
/// them all: a device that cannot fails the run (exit 5, naming it) before the arm is enabled.
fn open_and_start_devices(
    req: &RunRequest,
    target: &ArmTargetLink,
    runtime: &tokio::runtime::Handle,
    clock: MonotonicClock,
) -> Result<RunDevices, RunError> {
    let choice = DeviceChoice {
        camera: req.camera,
        light: req.light.clone(),
        trigger: req.trigger.clone(),
        stream: run_devices::camera::stream_config(
            req.camera,
            &req.camera_preset,
            req.camera_size,
        )?,
    };
    let ctx = run_devices::OpenContext {
        runtime,
        clock,
        #[cfg(feature = "stub")]
        sim: target.stub.as_ref().map(EmbeddedStub::scene),
    };
    #[cfg(not(feature = "stub"))]
    let _ = target;
    let mut devices = run_devices::open_devices(&choice, &ctx)?;
    devices.start(&choice.stream)?;
    Ok(devices)
}

/// Recorder, perception worker and frame intake: where telemetry and frames go.
struct CapturePath {
    recorder: Option<RecorderHandle>,
    record: Option<Telemetry>,
    perception: Option<hitl_perception::WorkerHandle>,
    estimates: Option<tokio::task::JoinHandle<u64>>,
    /// `--closed-loop`: every estimate, for the navigator (taken when the loop starts).
    navigation: std::sync::Mutex<Option<crossbeam::channel::Receiver<PoseResult>>>,
    /// How many estimates went that way (a simulated clock's lockstep waits on it).
    navigation_flow: Arc<EstimateFlow>,
    intake: Intake,
    queues: Arc<IntakeQueues>,
    live: Option<hitl_record::LiveServer>,
}

/// What closing the capture path gave.
struct ClosedCapture {
    intake: IntakeStats,
    estimates: u64,
    record_summary: Option<Result<(), String>>,
    live: Option<hitl_record::LiveSummary>,
}

impl CapturePath {
    fn start(
        req: &RunRequest,
        prepared: &Prepared,
        scene: &TargetScene,
        runtime: &tokio::runtime::Runtime,
    ) -> Result<Self, RunError> {
        let traj = &prepared.traj;
        let (live, tap) = start_live(req, runtime)?;
        let recorder = start_recorder(req, traj, &prepared.source, scene.scale, tap)?;
        let (recorder, record) = match recorder {
            Some((h, t)) => (Some(h), Some(t)),
            None => (None, None),
        };
        let (tee, navigation) = match req.closed_loop {
            Some(_) => {
                let (tx, rx) = crossbeam::channel::bounded(64);
                (Some(tx), Some(rx))
            }
            None => (None, None),
        };
        let navigation_flow = Arc::new(EstimateFlow::default());
        let (perception, estimates) = match &req.perception {
            BackendSpec::None => (None, None),
            spec => {
                let mesh = scene
                    .model
                    .lab_mesh(scene.scale)
                    .map_err(|e| RunError::BadInput(e.to_string()))?;
                let symmetry = scene.model.lab_symmetry(scene.scale);
                let estimator = backend_from_spec(spec, &mesh, &symmetry)
                    .map_err(|e| RunError::BadInput(format!("--perception: {e}")))?;
                match estimator {
                    None => (None, None),
                    Some(est) => {
                        let _guard = runtime.enter();
                        let (handle, mut results, _task) = spawn_worker(est, 4, 64, req.reregister);
                        let sink = record.clone();
                        let flow = Arc::clone(&navigation_flow);
                        let forward = runtime.spawn(async move {
                            let mut n = 0u64;
                            while let Some(r) = results.recv().await {
                                if let Some(tee) = &tee {
                                    // Never waits: a navigator that fell behind misses it.
                                    flow.count(tee.try_send(r.clone()).is_ok());
                                }
                                if let (Ok(est), Some(sink)) = (&r.estimate, &sink) {
                                    if let Some(pose) = est.pose {
                                        sink.push_pose_estimate(&PoseStamped {
                                            capture_ns: r.timestamp_ns,
                                            pose,
                                        });
                                    }
                                }
                                n += 1;
                            }
                            n
                        });
                        (Some(handle), Some(forward))
                    }
                }
            }
        };
        let mask = match req.mask {
            MaskSource::Sim => IntakeMask::Camera,
            MaskSource::None => IntakeMask::Dropped,
            MaskSource::Rendered => {
                let mesh = scene
                    .model
                    .lab_mesh(scene.scale)
                    .map_err(|e| RunError::BadInput(format!("--mask rendered: {e}")))?;
                let tripod = MaskDrawer::tripod_visible(req.camera == CameraSpec::Sim, &req.lab);
                let drawer = MaskDrawer::new(&mesh, &req.lab, tripod, req.mask_margin_px)
                    .map_err(RunError::BadInput)?;
                IntakeMask::Rendered(Box::new(drawer))
            }
        };
        let queues = Arc::new(IntakeQueues::new());
        let intake = Intake::spawn(
            Arc::clone(&queues),
            LabFrames::new(&req.lab),
            IntakeOutputs { record: record.clone(), perception: perception.clone() },
            mask,
        )
        .map_err(|e| RunError::Device(format!("capture intake thread: {e}")))?;
        let navigation = std::sync::Mutex::new(navigation);
        Ok(Self {
            recorder,
            record,
            perception,
            estimates,
            navigation,
            navigation_flow,
            intake,
            queues,
            live,
        })
    }

    /// Drain the intake, let perception finish, write the run's last event and close the file.
    fn close(
        self,
        runtime: &tokio::runtime::Runtime,
        outcome: &Outcome,
        device_faults: &[String],
    ) -> ClosedCapture {
        let intake = self.intake.finish();
        if let Some(p) = &self.perception {
            p.close();
        }
        let estimates = self.estimates.and_then(|f| runtime.block_on(f).ok()).unwrap_or(0);
        if let (Outcome::Tripped { trip, stopped }, Some(t)) = (outcome, &self.record) {
            let mut detail = format!("{}: {}", trip.kind.name(), trip.kind.detail());
            if !device_faults.is_empty() {
                detail.push_str(&format!(" ({})", device_faults.join("; ")));
            }
            t.push_event(SafetyEventMsg::text(
                trip.t_ns,
                if *stopped { EventKind::StopDone } else { EventKind::Other },
                format!(
                    "{detail}; {}",
                    if *stopped { "controlled stop completed" } else { "arm told to hold" }
                ),
            ));
        }
        let record_summary =
            self.recorder.map(|handle| handle.finish().map(|_| ()).map_err(|e| e.to_string()));
        // After the recorder: its tap is gone, so the live view's hand-off has ended.
        let live = self.live.map(hitl_record::LiveServer::close);
        ClosedCapture { intake, estimates, record_summary, live }
    }
}

/// The arm, connected and enabled, with its report stream.
struct ArmLink {
    arm: RunArm,
    reports: Option<SlotReader<ArmState>>,
    reader_stop: Arc<AtomicBool>,
    reader_thread: Option<std::thread::JoinHandle<()>>,
    /// How far the report reader has read (a simulated clock waits on it).
    #[cfg_attr(
        not(feature = "stub"),
        allow(dead_code, reason = "only the stub's simulated clock waits on it")
    )]
    reader_progress: Arc<sim_clock::ReaderProgress>,
    first: ArmState,
    /// The lab as this arm allows it (its joint table).
    lab: LabConfig,
    /// A second view of the reports, for the stop supervisor after the loop.
    stop_reports: SlotReader<ArmState>,
}

impl ArmLink {
    /// What a simulated clock's lockstep waits on.
    #[cfg_attr(
        not(feature = "stub"),
        allow(dead_code, reason = "only the stub has a simulated clock")
    )]
    fn watched(&self, capture: &CapturePath) -> sim_clock::Watched {
        sim_clock::Watched {
            commands_written: self.arm.written_counter(),
            reader: Arc::clone(&self.reader_progress),
            intake: Arc::clone(&capture.queues),
            perception: capture.perception.as_ref().map(|p| Arc::clone(&p.stats)),
            estimates_steer: true,
            navigator: None,
        }
    }

    /// Stop the report reader.
    fn close(&mut self) {
        self.reader_stop.store(true, Ordering::Release);
        if let Some(t) = self.reader_thread.take() {
            let _ = t.join();
        }
    }
}

/// A run that ends early (the approach refused, a thread that would not start) stops the reader
/// too.
impl Drop for ArmLink {
    fn drop(&mut self) {
        self.close();
    }
}

fn connect_arm(
    req: &RunRequest,
    target: &ArmTargetLink,
    traj: &Trajectory,
    table: &SetpointTable,
    clock: MonotonicClock,
) -> Result<ArmLink, RunError> {
    let thresholds = Thresholds::from_lab(&req.lab);
    let replies =
        ServoReplies::Pipelined { max_outstanding: thresholds.unanswered_setpoints(table.rate_hz) };
    let cmd_addr = target.cmd_addr;
    let mut arm = RunArm::connect(
        cmd_addr,
        ClientConfig { servo_replies: replies, ..ClientConfig::default() },
    )
    .map_err(|e| RunError::Device(format!("arm at {cmd_addr}: {e}")))?;
    let arm_lab = arm_link::identify_and_check(&mut arm, &req.lab, traj, table)?;
    let reader = connect_reports(
        target.report_host,
        target.report_port(ReportKind::Real),
        Some(target.report_port(ReportKind::Normal)),
        clock,
    )?;
    let (slot, mut reports) = LatestSlot::new();
    let reader_stop = Arc::new(AtomicBool::new(false));
    let reader_progress = Arc::new(sim_clock::ReaderProgress::default());
    let reader_thread = spawn_report_reader(
        reader,
        slot,
        Arc::clone(&reader_stop),
        Arc::clone(&reader_progress),
        req.rt.fifo_priority,
        req.clock == ClockChoice::Sim,
    )
    .map_err(|e| RunError::Device(format!("report reader thread: {e}")))?;
    let first = first_report(&mut reports, Duration::from_secs(2), || target.prime())
        .ok_or_else(|| RunError::Device("the arm sent no report within 2 s".into()))?;
    arm.enable_servo().map_err(|e| RunError::Device(format!("enabling the arm: {e}")))?;
    Ok(ArmLink {
        arm,
        stop_reports: reports.tap(),
        reports: Some(reports),
        reader_stop,
        reader_thread: Some(reader_thread),
        reader_progress,
        first,
        lab: arm_lab,
    })
}

/// How many ticks early level changes go out: `[light] lead_ms`, else the light kind's default
/// (docs/lights.md), said on stderr when not zero.
fn light_lead_ticks(req: &RunRequest, rate_hz: f64) -> u64 {
    let (lead_ms, from) = match req.lab.light.lead_ms {
        Some(ms) => (ms, "[light] lead_ms"),
        None => (run_devices::light::default_lead_ms(&req.light), "the light's default"),
    };
    let ticks = run_devices::light::lead_ticks(lead_ms, rate_hz);
    if ticks > 0 {
        crate::errln!(
            "light {}: level changes go out {lead_ms} ms ({ticks} ticks) early ({from})",
            req.light
        );
    }
    ticks
}

/// The approach from `start`, then the trajectory with its captures and light schedule, then the
/// retreat to `retreat_to` (the rest pose) when asked; with the planned moves.
fn build_program(
    start: &Joints,
    table: &SetpointTable,
    lab: &LabConfig,
    retreat_to: Option<&Joints>,
) -> Result<(Program, Vec<PlannedMove>), RunError> {
    let approach = plan_move_between("approach", start, &table.q[0], lab, table.rate_hz)?;
    let retreat = match retreat_to {
        Some(rest) => {
            let last = table.q[table.ticks() - 1];
            Some(plan_move_between("retreat", &last, rest, lab, table.rate_hz)?)
        }
        None => None,
    };
    let mut capture = vec![false; table.ticks()];
    for c in &table.captures {
        capture[c.tick] = true;
    }
    let program = Program {
        playback: (0..table.ticks())
            .map(|k| JointState { q: table.q[k], qd: table.qd[k], qdd: table.qdd[k] })
            .collect(),
        capture,
        light: table.light.clone().unwrap_or_default(),
        light_lead_ticks: 0,
        settle_tolerance_rad: 0.002,
        settle_max_ticks: (2.0 * table.rate_hz) as u64,
        lead_in_ticks: table.lead_in_ticks as u64,
        lead_out_ticks: table.lead_out_ticks as u64,
        approach: approach.setpoints.clone(),
        retreat: retreat.as_ref().map(|r| r.setpoints.clone()).unwrap_or_default(),
    };
    Ok((program, [Some(approach), retreat].into_iter().flatten().collect()))
}

/// `hitl park`'s stand-in for a trajectory: the rest pose held for one tick, so the steps of a run
/// (the stub, the arm's identity check, the recording) have one to name.
fn park_target(req: &RunRequest) -> Result<Prepared, RunError> {
    prepare::check_rate(req)?;
    let rest = req.lab.arm.rest_q;
    let traj = Trajectory {
        qpos: vec![rest, rest],
        t: vec![0.0, 1.0 / req.rate_hz],
        ..Default::default()
    };
    let table = SetpointTable::build(&traj, req.rate_hz, 1.0)
        .map_err(|e| RunError::BadInput(e.to_string()))?;
    Ok(Prepared { traj, table, source: Provenance::none() })
}

/// `hitl park`'s program: nothing but the retreat from `start` to the rest pose.
fn build_park_program(
    start: &Joints,
    table: &SetpointTable,
    lab: &LabConfig,
) -> Result<(Program, Vec<PlannedMove>), RunError> {
    let retreat = plan_move_between("retreat", start, &lab.arm.rest_q, lab, table.rate_hz)?;
    let program = Program {
        settle_tolerance_rad: 0.002,
        settle_max_ticks: (2.0 * table.rate_hz) as u64,
        retreat: retreat.setpoints.clone(),
        ..Program::default()
    };
    Ok((program, vec![retreat]))
}

/// What the loop left.
struct Played {
    /// On a simulated clock: simulated and host time the loop took.
    sim: Option<SimStats>,
    outcome: Outcome,
    rt: rt::RtReport,
    status: Arc<LoopStatus>,
    captures: u64,
    closed_loop: Option<NavigatorSummary>,
}

/// Play `program` on the real-time thread, the loop borrowing the arm and the devices; progress
/// is followed on this thread.
#[allow(clippy::too_many_arguments)]
fn play(
    req: &RunRequest,
    program: &Program,
    table: &SetpointTable,
    link: &mut ArmLink,
    devices: &mut RunDevices,
    capture: &CapturePath,
    operator_stop: Arc<AtomicBool>,
    clock: &MonotonicClock,
    target: &ArmTargetLink,
    plan_frame: Option<PlanFrame>,
) -> Result<Played, RunError> {
    let health = Health {
        operator_stop,
        recorder: capture.recorder.as_ref().map(|h| h.health()),
        ..Health::default()
    };
    let status = Arc::new(LoopStatus::default());
    let (planner, stop) = StopPlanner::start(stop_limits(&req.lab), table.dt, 10.0)
        .map_err(|e| RunError::Device(format!("stop planner thread: {e}")))?;
    let reports =
        link.reports.take().ok_or_else(|| RunError::Device("arm reports already taken".into()))?;
    let io = LoopIo {
        reports,
        telemetry: RunTelemetry {
            record: capture.record.clone(),
            intake: Arc::clone(&capture.queues),
        },
        status: Arc::clone(&status),
        health,
        stop,
        clock: clock.clone(),
    };
    let interlocks = Interlocks::new(Thresholds::from_lab(&req.lab));
    let (correction, navigator, turns) = start_navigator(
        req,
        program,
        table,
        &link.lab,
        capture,
        &status,
        clock.clone(),
        plan_frame,
    )?;
    #[cfg(feature = "stub")]
    let sim = target.sim_stub().zip(clock.sim_time().cloned());
    #[cfg(feature = "stub")]
    let (watched, times) = (
        // Without a closed loop nothing in the tick reads the estimates.
        sim_clock::Watched {
            estimates_steer: req.closed_loop.is_some(),
            navigator: turns,
            ..link.watched(capture)
        },
        sim_clock::WorldTimes::default(),
    );
    #[cfg(not(feature = "stub"))]
    let _ = (target, turns);
    #[cfg(feature = "stub")]
    let stop_planned = || planner.settled();
    #[cfg(feature = "stub")]
    let (sim_time, times) = (sim.as_ref().map(|(_, t)| t.clone()), &times);
    let wall = std::time::Instant::now();
    let rt_options = req.rt;
    let rate = table.rate_hz;
    let start_q = link.first.q;
    let arm = &mut link.arm;
    let (outcome, rt_report) = std::thread::scope(|scope| {
        let rt_thread = std::thread::Builder::new()
            .name("hitl-rt".into())
            .spawn_scoped(scope, move || {
                let rt_report = rt::os::apply(&rt_options);
                let loop_devices = Devices {
                    arm: &mut *arm,
                    camera: &mut devices.camera,
                    light: &mut devices.light,
                    inputs: &mut devices.inputs,
                    trigger: &mut devices.trigger,
                };
                let control =
                    ControlLoop::new(program, loop_devices, io, interlocks, rate, &start_q)
                        .with_correction(correction);
                #[cfg(feature = "stub")]
                let outcome = match sim {
                    Some((stub, time)) => {
                        let world = sim_clock::SimWorld {
                            stub,
                            watched: &watched,
                            stop_planned: &stop_planned,
                            times,
                        };
                        let period_ns = (1e9 / rate).round() as u64;
                        control.run_paced(&mut rt::Lockstep::new(time, period_ns, world))
                    }
                    None => control.run(rt_options.spin),
                };
                #[cfg(not(feature = "stub"))]
                let outcome = control.run(rt_options.spin);
                let _ = arm.flush_servo_replies();
                (outcome, rt_report)
            })
            .map_err(|e| RunError::Device(format!("real-time thread: {e}")))?;
        progress::follow(&status, program, req.plain_progress);
        rt_thread.join().map_err(|_| RunError::Device("the real-time thread panicked".into()))
    })?;
    let wall_s = wall.elapsed().as_secs_f64();
    drop(planner);
    let closed_loop = navigator.map(|n| finish_navigator(req, n, capture));
    let captures = status.captures.load(Ordering::Acquire);
    #[cfg(feature = "stub")]
    let sim = sim_time.map(|time| times.stats(time.now_ns(), wall_s));
    #[cfg(not(feature = "stub"))]
    let sim = None;
    let _ = wall_s;
    Ok(Played { outcome, rt: rt_report, status, captures, closed_loop, sim })
}

/// The stop planner's limits: the lab's joint velocity, acceleration and jerk.
fn stop_limits(lab: &LabConfig) -> MoveLimits {
    let limits = &lab.limits;
    MoveLimits {
        velocity: limits.velocity_rad_s,
        acceleration: limits.acceleration_rad_s2,
        jerk: limits.jerk_rad_s3,
    }
}

/// The tick's correction stage, the navigator and, on a simulated clock, its turns.
type NavigatorStart = (CorrectionStage, Option<Navigator>, Option<Arc<NavigatorTurns>>);

/// `--closed-loop`: the tick's correction stage and the navigator that feeds it, and on a
/// simulated clock the navigator's turns for the lockstep (open loop: a stage that does nothing,
/// no navigator).
#[allow(clippy::too_many_arguments)]
fn start_navigator(
    req: &RunRequest,
    program: &Program,
    table: &SetpointTable,
    lab: &LabConfig,
    capture: &CapturePath,
    status: &Arc<LoopStatus>,
    clock: MonotonicClock,
    plan_frame: Option<PlanFrame>,
) -> Result<NavigatorStart, RunError> {
    let (Some(config), Some(frame)) = (req.closed_loop, plan_frame) else {
        return Ok((CorrectionStage::open_loop(), None, None));
    };
    let turns = clock
        .sim_time()
        .map(|_| TurnTaker::new(Arc::clone(&capture.navigation_flow), Arc::clone(status)));
    let lockstep = turns.as_ref().map(|t| Arc::clone(&t.turns));
    let results = capture.navigation.lock().ok().and_then(|mut r| r.take()).ok_or_else(|| {
        RunError::Device("--closed-loop: no pose estimates to navigate on".into())
    })?;
    let first_tick = program.approach.len() as u64;
    let capture_ticks = program
        .capture
        .iter()
        .enumerate()
        .filter(|(_, c)| **c)
        .map(|(i, _)| first_tick + i as u64)
        .collect();
    let queues = CorrectionQueues::new(4);
    let navigator = Navigator::spawn(NavigatorInputs {
        frame,
        config,
        lab: lab.clone(),
        plan: PlanTicks { first_tick, playback: program.playback.clone() },
        capture_ticks,
        dt: table.dt,
        results,
        queues: queues.clone(),
        status: Arc::clone(status),
        record: capture.record.clone(),
        clock,
        perception: capture.perception.clone(),
        turns,
    })
    .map_err(|e| RunError::Device(format!("closed-loop navigator thread: {e}")))?;
    Ok((CorrectionStage::closed_loop(queues), Some(navigator), lockstep))
}

/// Stop the navigator and record what the closed loop did in the run's `closed_loop` metadata.
fn finish_navigator(req: &RunRequest, n: Navigator, capture: &CapturePath) -> NavigatorSummary {
    let summary = n.finish();
    if let Some(t) = &capture.record {
        t.push_metadata("closed_loop", closed_loop_metadata(req, &summary));
    }
    summary
}

/// The run's `closed_loop` metadata record: the settings and what the closed loop did.
fn closed_loop_metadata(
    req: &RunRequest,
    s: &NavigatorSummary,
) -> std::collections::BTreeMap<String, String> {
    let mut m = std::collections::BTreeMap::new();
    if let Some(c) = &req.closed_loop {
        m.insert("corridor_m".into(), c.corridor_m.to_string());
        m.insert("fallback_after".into(), c.fallback_after.to_string());
        m.insert("max_age_s".into(), c.max_age_s.to_string());
        m.insert("hold_s".into(), c.hold_s.to_string());
        if let Some(d) = c.drill_perception_offset {
            m.insert("drill_perception_offset_m".into(), d.offset_m.to_string());
            m.insert("drill_perception_offset_s".into(), d.from_s.to_string());
        }
    }
    for (k, v) in [
        ("accepted", s.accepted),
        ("gated", s.gated),
        ("lost", s.lost),
        ("late", s.late),
        ("missing", s.missing),
        ("segments", s.segments),
        ("refused", s.refused),
    ] {
        m.insert(k.into(), v.to_string());
    }
    m.insert("max_correction_m".into(), s.max_correction_m.to_string());
    m.insert("fallback".into(), s.fallback.clone().unwrap_or_default());
    m
}

/// After the loop: hand the frames still on their way to the intake, stop every device (a last
/// light frame, the trigger box's queue written and answered, ports closed), record the fires
/// answered after the last tick, and say which devices failed.
fn close_devices(devices: &mut RunDevices, capture: &CapturePath, captures: u64) -> Vec<String> {
    collect_late_frames(&mut devices.camera, &capture.queues, captures);
    let faults = devices.faults();
    for failed in devices.stop() {
        crate::errln!("note: {failed}");
    }
    let telemetry =
        RunTelemetry { record: capture.record.clone(), intake: Arc::clone(&capture.queues) };
    telemetry.record_late_fires(&mut devices.trigger);
    faults
}

fn report(
    req: &RunRequest,
    program: &Program,
    played: Played,
    closed: ClosedCapture,
    stub_final_q: Option<Joints>,
    device_faults: Vec<String>,
) -> RunReport {
    let mut exit_code = match played.outcome {
        Outcome::Completed { .. } => exit::OK,
        Outcome::Tripped { trip, .. } => trip.kind.exit_code(),
    };
    let recording_failed = matches!(closed.record_summary, Some(Err(_)));
    if exit_code == exit::OK && recording_failed {
        exit_code = exit::INTERLOCK;
    }
    for line in &played.rt.fallbacks {
        crate::errln!("note: {line}");
    }
    RunReport {
        outcome: played.outcome,
        exit_code,
        approach_ticks: program.approach.len(),
        playback_ticks: program.playback.len(),
        retreat_ticks: program.retreat.len(),
        captures: played.captures,
        max_late_ns: played.status.max_late_ns.load(Ordering::Relaxed),
        overruns: played.status.overruns.load(Ordering::Relaxed),
        rt: played.rt,
        stub_final_q,
        recording: req.record.clone(),
        intake: closed.intake,
        estimates: closed.estimates,
        record_error: closed.record_summary.and_then(|r| r.err()),
        device_faults,
        box_stop: None,
        live: closed.live,
        closed_loop: played.closed_loop,
        sim: played.sim,
    }
}
