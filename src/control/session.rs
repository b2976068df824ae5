//! A run from start to exit code: load and preflight, connect, open devices, enable, plan and
//! check the approach, play on the real-time thread, settle, stop, close. Everything that
//! allocates or blocks happens here, before or after the loop; the loop itself is [`super::tick`].

use super::interlocks::{Interlocks, Thresholds};
use super::motion::{plan_move, MoveLimits};
use super::setpoint::Setpoint;
use super::stop::StopPlanner;
use super::telemetry::LoopStatus;
use super::tick::{ControlLoop, Devices, Health, LoopIo, Outcome, Program};
use crate::capture::intake::{Intake, IntakeOutputs, IntakeStats};
#[cfg(feature = "stub")]
use crate::capture::sim_light::SimLight;
use crate::capture::sink::{IntakeQueues, RunTelemetry};
use crate::capture::truth::LabFrames;
use crate::devices::any::{RunCamera, RunLight};
use crate::devices::inputs::RunInputs;
use crate::devices::none::{NoCamera, NoInputs, NoLight};
use crate::exit;
use crate::rt::{self, slot::LatestSlot, RtOptions};
use hitl_drivers::light::{LightSpec, SerialLight};
use hitl_drivers::xarm::{ClientConfig, ReportConfig, ReportKind, ReportReader, XarmClient};
use hitl_hal::RgbdCamera as _;
use hitl_hal::{Arm, ArmReports, ArmState, Joints, MonotonicClock};
use hitl_perception::{backend_from_spec, spawn_worker, BackendSpec, ReregisterPolicy};
use hitl_record::{
    EventKind, PoseStamped, Recorder, RecorderHandle, RunMetadata, SafetyEventMsg, SunPhaseTrack,
    Telemetry,
};
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::timing::SetpointTable;
use hitl_trajectories::{npz, preflight, Trajectory};
use sha2::Digest as _;
use std::net::{IpAddr, SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
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
    /// Simulated camera intrinsics preset (nfov, wfov, orbbec) and size.
    pub camera_preset: String,
    pub camera_size: Option<(u32, u32)>,
    /// Target model: a built-in name (asymmetric, one-plane, two-planes) or an OBJ/STL path.
    pub target_model: String,
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
    pub intake: IntakeStats,
    /// Pose estimates the perception worker returned.
    pub estimates: u64,
    /// Why the recording could not be closed properly, if so.
    pub record_error: Option<String>,
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
        if self.intake.frames > 0 {
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
        crate::errln!("warning: {warning}");
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
///
/// Two shapes are tried, each a chain of Ruckig rest-to-rest moves: the direct joint-space move,
/// then one that first turns base and wrist while shoulder and elbow stay where they are (the arm
/// keeps its reach) and extends only at the end. The first that passes every preflight rule is
/// taken; when none does, the run is refused with the direct move's violations.
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

fn resolve(host: &str, port: u16) -> Result<SocketAddr, RunError> {
    (host, port)
        .to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| RunError::BadInput(format!("cannot resolve arm address '{host}'")))
}

/// The report reader thread: reports into the latest-value slot until told to stop or the
/// stream fails (then the tick's watchdog trips).
///
/// The reports are the loop's only view of the arm, so when the loop runs on SCHED_FIFO the
/// reader runs just below it (`fifo_priority - 1`): perception, rendering or recording on the
/// normal scheduler cannot make the watchdog see a silence the arm did not cause. Refused, it
/// stays on the normal scheduler (the loop's own report already says real-time was refused).
fn spawn_report_reader(
    mut reader: ReportReader,
    slot: LatestSlot<ArmState>,
    stop: Arc<AtomicBool>,
    fifo_priority: Option<i32>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new().name("hitl-reports".into()).spawn(move || {
        if let Some(p) = fifo_priority {
            let _ = rt::os::set_fifo_priority((p - 1).max(1));
        }
        while !stop.load(Ordering::Acquire) {
            match reader.next_report() {
                Ok(state) => slot.publish(state),
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

/// The embedded stub, when the run targets it: the arm server, and the pieces of the scene the
/// simulated camera and light share with it.
#[cfg(feature = "stub")]
struct EmbeddedStub {
    handle: hitl_sim_stub::StubHandle,
    lab_model: hitl_sim_stub::mujoco_plant::LabModel,
    arm: hitl_sim_stub::mujoco_plant::SharedArmState,
    light: hitl_sim_stub::camera::LightLevel,
}

#[cfg(feature = "stub")]
fn start_stub(
    faults: &[String],
    lab: &LabConfig,
    target: &TargetScene,
) -> Result<EmbeddedStub, RunError> {
    use hitl_sim_stub::mjcf::TargetModel as StubTarget;
    use hitl_sim_stub::mujoco_plant::{LabModel, MujocoPlant};
    use hitl_sim_stub::{Fault, Stub, StubConfig};
    let faults = faults
        .iter()
        .map(|s| s.parse::<Fault>().map_err(|e| RunError::BadInput(e.to_string())))
        .collect::<Result<Vec<_>, _>>()?;
    let stub_target = StubTarget {
        mesh: Some(target.model.vertices_faces()),
        greatest_dimension_m: target.model.greatest_dimension_m() * target.scale,
    };
    let lab_model = LabModel::generated(lab, &stub_target)
        .map_err(|e| RunError::Device(format!("stub scene: {e}")))?;
    let plant = MujocoPlant::from_lab_model(lab_model.clone());
    let arm = plant.shared_state();
    let config = StubConfig { faults, ..StubConfig::ephemeral() };
    let handle =
        Stub::start(config, Box::new(plant)).map_err(|e| RunError::Device(format!("stub: {e}")))?;
    Ok(EmbeddedStub { handle, lab_model, arm, light: Default::default() })
}

/// The target the camera looks at: its model and the lab scale (lab metres per real metre).
struct TargetScene {
    model: hitl_perception::TargetModel,
    scale: f64,
}

/// The target model and the scale the trajectory was planned at (its `meta.scale`); without one,
/// the model is sized to the lab's target keep-out (or the printed model's size).
fn target_scene(req: &RunRequest, traj: &Trajectory) -> Result<TargetScene, RunError> {
    let model = hitl_perception::TargetModel::from_spec(&req.target_model)
        .map_err(|e| RunError::BadInput(format!("--target-model: {e}")))?;
    let planned = traj
        .meta
        .as_deref()
        .and_then(|m| serde_json::from_str::<serde_json::Value>(m).ok())
        .and_then(|v| v.get("scale")?.as_f64())
        .filter(|s| *s > 0.0 && s.is_finite());
    let lab_size = req.lab.target.model_size_m.unwrap_or(2.0 * req.lab.target.keepout_radius_m);
    let scale = planned.unwrap_or(lab_size / model.greatest_dimension_m());
    Ok(TargetScene { model, scale })
}

/// A perception pose (4x4 matrix) as the recorder's pose.
fn record_pose(m: &nalgebra::Matrix4<f64>) -> hitl_record::Pose {
    let rows: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
    hitl_record::Pose::from_matrix(&rows)
}

/// The run's devices besides the arm, opened before anything moves.
struct RunDevices {
    camera: RunCamera,
    light: RunLight,
    inputs: RunInputs,
}

/// Open camera, light and inputs as asked; a device that cannot be opened fails the run (exit 5)
/// before the arm is enabled.
fn open_devices(
    req: &RunRequest,
    #[cfg(feature = "stub")] stub: Option<&EmbeddedStub>,
    clock: MonotonicClock,
) -> Result<RunDevices, RunError> {
    let spec: LightSpec =
        req.light.parse().map_err(|e: hitl_drivers::light::spec::LightSpecError| {
            RunError::BadInput(e.to_string())
        })?;
    #[cfg(feature = "stub")]
    let sim_needed = |what: &str| -> Result<&EmbeddedStub, RunError> {
        stub.ok_or_else(|| {
            RunError::BadInput(format!("--{what} sim needs the embedded stub (no --arm)"))
        })
    };
    let light = match &spec {
        LightSpec::None => RunLight::None(NoLight),
        #[cfg(feature = "stub")]
        LightSpec::Sim => RunLight::Sim(SimLight(sim_needed("light")?.light.clone())),
        #[cfg(not(feature = "stub"))]
        LightSpec::Sim => {
            return Err(RunError::BadInput("--light sim needs the stub feature".into()))
        }
        other => {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| RunError::Device(format!("light: {e}")))?;
            let light = rt
                .block_on(SerialLight::open(other, clock))
                .map_err(|e| RunError::Device(format!("light {other}: {e}")))?;
            match light {
                Some(l) => RunLight::Serial(l),
                None => RunLight::None(NoLight),
            }
        }
    };
    let camera = match req.camera.as_str() {
        "none" => RunCamera::None(NoCamera),
        #[cfg(feature = "stub")]
        "sim" => {
            use hitl_sim_stub::camera::{Preset, SimCamera, SimCameraConfig};
            let s = sim_needed("camera")?;
            let preset = Preset::from_name(&req.camera_preset).ok_or_else(|| {
                RunError::BadInput(format!(
                    "--camera-preset {}: expected nfov, wfov or orbbec",
                    req.camera_preset
                ))
            })?;
            let intrinsics = match req.camera_size {
                Some((w, h)) => preset.at(w, h),
                None => preset.intrinsics(),
            };
            let config = SimCameraConfig { intrinsics, clock, ..Default::default() };
            let mut cam =
                SimCamera::new(s.lab_model.clone(), s.arm.clone(), s.light.clone(), config)
                    .map_err(|e| RunError::Device(e.to_string()))?;
            cam.arm_trigger().map_err(|e| RunError::Device(e.to_string()))?;
            RunCamera::Sim(Box::new(cam))
        }
        "orbbec" => {
            use hitl_drivers::orbbec::{OrbbecCamera, OrbbecOptions};
            let mut cam = OrbbecCamera::open(OrbbecOptions { clock, ..Default::default() })
                .map_err(|e| RunError::Device(e.to_string()))?;
            cam.arm_trigger().map_err(|e| RunError::Device(format!("Orbbec camera: {e}")))?;
            RunCamera::Orbbec(Box::new(cam))
        }
        other => {
            return Err(RunError::BadInput(format!(
                "--camera {other}: expected sim, orbbec or none"
            )))
        }
    };
    #[cfg(feature = "stub")]
    let inputs = match stub {
        Some(s) => RunInputs::Sim(s.handle.inputs()),
        None => RunInputs::None(NoInputs),
    };
    #[cfg(not(feature = "stub"))]
    let inputs = RunInputs::None(NoInputs);
    Ok(RunDevices { camera, light, inputs })
}

/// Start the recorder, when asked: the `run` metadata record first.
fn start_recorder(
    req: &RunRequest,
    traj: &Trajectory,
    scale: f64,
) -> Result<Option<(RecorderHandle, Telemetry)>, RunError> {
    let Some(path) = &req.record else { return Ok(None) };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| RunError::BadInput(format!("cannot create {}: {e}", dir.display())))?;
    }
    let bytes = std::fs::read(&req.trajectory).unwrap_or_default();
    let sha = sha2::Sha256::digest(&bytes);
    let mut versions = std::collections::BTreeMap::new();
    versions.insert("hitl".to_string(), env!("CARGO_PKG_VERSION").to_string());
    let meta = RunMetadata {
        config: serde_json::json!({
            "trajectory": req.trajectory.display().to_string(),
            "rate_hz": req.rate_hz,
            "speed_scale": req.speed_scale,
            "camera": req.camera,
            "light": req.light,
            "perception": req.perception,
            "target_model": req.target_model,
            "arm": match &req.target { ArmTarget::Stub { faults } => format!("stub (faults: {faults:?})"), ArmTarget::Remote { host } => host.clone() },
        })
        .to_string(),
        trajectory_sha256: sha.iter().map(|b| format!("{b:02x}")).collect(),
        trajectory_meta: traj.meta.clone().unwrap_or_default(),
        lab_config: req.lab.to_toml(),
        versions,
        scale: Some(scale),
        extra: [("target_model".to_string(), req.target_model.clone())].into(),
        sun_phase: traj.sun_phase_deg.as_ref().map(|deg| SunPhaseTrack {
            t_s: traj.t.iter().map(|t| t / req.speed_scale).collect(),
            sun_phase_deg: deg.clone(),
        }),
    };
    Recorder::spawn(path, &meta)
        .map(Some)
        .map_err(|e| RunError::BadInput(format!("cannot record to {}: {e}", path.display())))
}

/// Play `req` and say how it ended.
pub fn run(req: RunRequest) -> Result<RunReport, RunError> {
    // Ctrl-C from the very start: during setup it stops the run at its first tick, with no motion.
    let operator_stop = Arc::new(AtomicBool::new(false));
    install_ctrlc(&operator_stop);
    let (traj, table) = prepare(&req)?;
    let scene = target_scene(&req, &traj)?;
    let backend: BackendSpec =
        req.perception.parse().map_err(|e: hitl_perception::PerceptionError| {
            RunError::BadInput(format!("--perception: {e}"))
        })?;
    let clock = MonotonicClock::new();

    // The arm: the embedded stub, or the real box.
    #[cfg(feature = "stub")]
    let stub = match &req.target {
        ArmTarget::Stub { faults } => Some(start_stub(faults, &req.lab, &scene)?),
        ArmTarget::Remote { .. } => None,
    };
    let (cmd_addr, report_host) = match &req.target {
        #[cfg(feature = "stub")]
        ArmTarget::Stub { .. } => {
            let addr = stub
                .as_ref()
                .map(|s| s.handle.cmd_addr())
                .ok_or_else(|| RunError::Device("stub did not start".into()))?;
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

    // Devices, recorder and perception, all before the arm is enabled.
    let devices = open_devices(
        &req,
        #[cfg(feature = "stub")]
        stub.as_ref(),
        clock,
    )?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| RunError::Device(format!("async runtime: {e}")))?;
    let recorder = start_recorder(&req, &traj, scene.scale)?;
    let record_telemetry = recorder.as_ref().map(|(_, t)| t.clone());
    let (perception, estimates) = match &backend {
        BackendSpec::None => (None, None),
        spec => {
            let mesh =
                scene.model.lab_mesh(scene.scale).map_err(|e| RunError::BadInput(e.to_string()))?;
            let estimator = backend_from_spec(spec, &mesh)
                .map_err(|e| RunError::BadInput(format!("--perception: {e}")))?;
            match estimator {
                None => (None, None),
                Some(est) => {
                    let _guard = runtime.enter();
                    let (handle, mut results, _task) =
                        spawn_worker(est, 4, 64, ReregisterPolicy::default());
                    let sink = record_telemetry.clone();
                    let forward = runtime.spawn(async move {
                        let mut n = 0u64;
                        while let Some(r) = results.recv().await {
                            if let (Ok(est), Some(sink)) = (&r.estimate, &sink) {
                                if let Some(m) = est.pose {
                                    sink.push_pose_estimate(&PoseStamped {
                                        capture_ns: r.timestamp_ns,
                                        pose: record_pose(&m),
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
    let intake_queues = Arc::new(IntakeQueues::new());
    let intake = Intake::spawn(
        Arc::clone(&intake_queues),
        LabFrames::new(&req.lab),
        IntakeOutputs { record: record_telemetry.clone(), perception: perception.clone() },
    )
    .map_err(|e| RunError::Device(format!("capture intake thread: {e}")))?;

    // Connect and enable the arm.
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
    let reader_thread =
        spawn_report_reader(reader, slot, Arc::clone(&reader_stop), req.rt.fifo_priority)
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

    let health = Health {
        operator_stop,
        recorder: recorder.as_ref().map(|(h, _)| h.health()),
        ..Health::default()
    };
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
    let io = LoopIo {
        reports,
        telemetry: RunTelemetry {
            record: record_telemetry.clone(),
            intake: Arc::clone(&intake_queues),
        },
        status: Arc::clone(&status),
        health,
        stop,
        clock,
    };
    let RunDevices { camera, light, inputs } = devices;
    let late_frames = Arc::clone(&intake_queues);
    let rt_options = req.rt;
    let rate = table.rate_hz;
    let start_q = first.q;
    let status_rt = Arc::clone(&status);
    let (outcome, rt_report) = std::thread::scope(|scope| {
        let program = &program;
        let rt_thread = std::thread::Builder::new()
            .name("hitl-rt".into())
            .spawn_scoped(scope, move || {
                let rt_report = rt::os::apply(&rt_options);
                let devices = Devices { arm, camera, light, inputs };
                let control = ControlLoop::new(program, devices, io, interlocks, rate, &start_q);
                let (outcome, mut devices) = control.run(rt_options.spin);
                let _ = devices.arm.flush_servo_replies();
                collect_late_frames(
                    &mut devices.camera,
                    &late_frames,
                    status_rt.captures.load(Ordering::Acquire),
                );
                (outcome, rt_report)
            })
            .map_err(|e| RunError::Device(format!("real-time thread: {e}")))?;
        super::progress::follow(&status, program, req.plain_progress);
        rt_thread.join().map_err(|_| RunError::Device("the real-time thread panicked".into()))
    })?;
    drop(planner);
    reader_stop.store(true, Ordering::Release);
    let _ = reader_thread.join();

    // Let the last frames arrive, then close the capture path and the recording.
    std::thread::sleep(Duration::from_millis(300));
    let intake_stats = intake.finish();
    if let Some(p) = &perception {
        p.close();
    }
    let estimates_forwarded = estimates.and_then(|f| runtime.block_on(f).ok()).unwrap_or(0);
    if let (Outcome::Tripped { trip, stopped }, Some(t)) = (&outcome, &record_telemetry) {
        t.push_event(SafetyEventMsg::text(
            trip.t_ns,
            if *stopped { EventKind::StopDone } else { EventKind::Other },
            format!(
                "{}: {}; {}",
                trip.kind.name(),
                trip.kind.detail(),
                if *stopped { "controlled stop completed" } else { "arm told to hold" }
            ),
        ));
    }
    let record_summary = recorder.map(|(handle, _)| handle.finish().map_err(|e| e.to_string()));

    #[cfg(feature = "stub")]
    let stub_final_q = stub.map(|s| {
        let q = s.handle.plant_joints();
        s.handle.shutdown();
        q
    });
    #[cfg(not(feature = "stub"))]
    let stub_final_q = None;

    let mut exit_code = match outcome {
        Outcome::Completed { .. } => exit::OK,
        Outcome::Tripped { trip, .. } => trip.kind.exit_code(),
    };
    let recording_failed = matches!(record_summary, Some(Err(_)));
    if exit_code == exit::OK && recording_failed {
        exit_code = exit::INTERLOCK;
    }
    for line in &rt_report.fallbacks {
        crate::errln!("note: {line}");
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
        intake: intake_stats,
        estimates: estimates_forwarded,
        record_error: record_summary.and_then(|r| r.err()),
    })
}

/// After the loop: frames for the last captures may still be on their way; hand them to the
/// intake (up to 2 s), so every capture is recorded or reported.
fn collect_late_frames(camera: &mut RunCamera, intake: &IntakeQueues, fired: u64) {
    let deadline = Instant::now() + Duration::from_secs(2);
    while Instant::now() < deadline {
        match camera.poll_frame() {
            Ok(Some(frame)) => {
                intake.frames_in.fetch_add(1, Ordering::Relaxed);
                if intake.frames.push(frame).is_err() {
                    intake.frames_lost.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(None) => {
                let delivered = intake.frames_in.load(Ordering::Relaxed);
                if matches!(camera, RunCamera::None(_)) || delivered >= fired {
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => break,
        }
    }
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

/// Ctrl-C asks for a controlled stop. An impatient second press must not cut that stop short
/// (the arm would be left on whatever setpoint came last), so it only says what is happening; a
/// third press abandons the stop and ends the process (exit 130), for a stop that cannot finish.
fn install_ctrlc(operator_stop: &Arc<AtomicBool>) {
    let flag = Arc::clone(operator_stop);
    let presses = AtomicU32::new(0);
    let _ = ctrlc::set_handler(move || {
        flag.store(true, Ordering::Release);
        match presses.fetch_add(1, Ordering::AcqRel) {
            0 => {}
            1 => crate::errln!(
                "hitl: controlled stop in progress; Ctrl-C once more abandons it and exits"
            ),
            _ => std::process::exit(i32::from(exit::OPERATOR_STOP)),
        }
    });
}
