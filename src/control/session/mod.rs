//! A run from start to exit code: load and preflight, connect, open devices, enable, plan and
//! check the approach, play on the real-time thread, settle, stop, close. Everything that
//! allocates or blocks happens here, before or after the loop; the loop itself is [`super::tick`].
//!
//! - [`prepare`]: load, time-parametrise and preflight; plan the approach by the same rules;
//! - [`arm_link`]: the arm's address, report reader, first report, and the embedded stub;
//! - [`devices`]: camera, light, inputs, the target scene, the recorder, late frames;
//! - [`operator`]: what Ctrl-C does.

mod arm_link;
mod devices;
mod operator;
mod prepare;

use crate::capture::intake::{Intake, IntakeOutputs, IntakeStats};
use crate::capture::sink::{IntakeQueues, RunTelemetry};
use crate::capture::truth::LabFrames;
use crate::control::interlocks::{Interlocks, Thresholds};
use crate::control::motion::MoveLimits;
use crate::control::setpoint::Setpoint;
use crate::control::stop::StopPlanner;
use crate::control::telemetry::LoopStatus;
use crate::control::tick::{ControlLoop, Devices, Health, LoopIo, Outcome, Program};
use crate::exit;
use crate::rt::{self, slot::LatestSlot, RtOptions};
#[cfg(feature = "stub")]
use arm_link::start_stub;
use arm_link::{connect_reports, first_report, resolve, spawn_report_reader};
use devices::{
    collect_late_frames, open_devices, record_pose, start_recorder, target_scene, RunDevices,
};
use hitl_drivers::xarm::{ClientConfig, ReportKind, ServoReplies, XarmClient};
use hitl_hal::{Arm, Joints, MonotonicClock};
use hitl_perception::{backend_from_spec, spawn_worker, BackendSpec, ReregisterPolicy};
use hitl_record::{ChunkCompression, EventKind, PoseStamped, SafetyEventMsg};
use hitl_trajectories::lab::LabConfig;
use operator::install_ctrlc;
use prepare::{plan_approach, prepare};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

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
    /// Chunk compression of the recording.
    pub record_compression: ChunkCompression,
    pub camera: String,
    pub light: String,
    pub perception: String,
    /// When the perception backend re-registers beyond its first frame and a lost track.
    pub reregister: ReregisterPolicy,
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
    if backend == BackendSpec::None && req.reregister != ReregisterPolicy::default() {
        return Err(RunError::BadInput(
            "--reregister-every and --reregister-residual-m need a pose estimator \
             (--perception icp|onnx:MODEL|socket:PATH)"
                .into(),
        ));
    }
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
                    let (handle, mut results, _task) = spawn_worker(est, 4, 64, req.reregister);
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
    let thresholds = Thresholds::from_lab(&req.lab);
    let replies =
        ServoReplies::Pipelined { max_outstanding: thresholds.unanswered_setpoints(table.rate_hz) };
    let mut arm = XarmClient::connect(
        cmd_addr,
        ClientConfig { servo_replies: replies, ..ClientConfig::default() },
    )
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
    let interlocks = Interlocks::new(thresholds);
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
