//! What the session keeps around the devices: the target scene the camera looks at, the
//! recorder (with the run's choices in its metadata), and the frames still on their way after
//! the loop. Opening the devices is `crate::devices`.

use super::prepare::Provenance;
use super::{ArmTarget, RunError, RunRequest};
use crate::capture::sink::IntakeQueues;
use crate::devices::RunCamera;
use hitl_hal::RgbdCamera as _;
use hitl_perception::BackendSpec;
use hitl_record::{
    LiveServer, LiveTap, Recorder, RecorderConfig, RecorderHandle, RunMetadata, SunPhaseTrack,
    Telemetry,
};
use hitl_trajectories::Trajectory;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// The target the camera looks at: its model and the lab scale (lab metres per real metre).
pub(super) struct TargetScene {
    pub(super) model: hitl_perception::TargetModel,
    pub(super) scale: f64,
}

/// The target model and the scale the trajectory was planned at (its `meta.scale`); without one,
/// the model is sized to the lab's target keep-out (or the printed model's size).
pub(super) fn target_scene(req: &RunRequest, traj: &Trajectory) -> Result<TargetScene, RunError> {
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

/// Start the recorder, when asked: the `run` metadata record first.
pub(super) fn start_recorder(
    req: &RunRequest,
    traj: &Trajectory,
    source: &Provenance,
    scale: f64,
    live: Option<LiveTap>,
) -> Result<Option<(RecorderHandle, Telemetry)>, RunError> {
    let Some(path) = &req.record else { return Ok(None) };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| RunError::BadInput(format!("cannot create {}: {e}", dir.display())))?;
    }
    let mut versions = std::collections::BTreeMap::new();
    versions.insert("hitl".to_string(), env!("CARGO_PKG_VERSION").to_string());
    let meta = RunMetadata {
        config: serde_json::json!({
            "trajectory": source.name,
            "rate_hz": req.rate_hz,
            "speed_scale": req.speed_scale,
            "camera": req.camera.to_string(),
            "camera_preset": req.camera_preset,
            "camera_size": req.camera_size,
            "light": req.light.to_string(),
            "trigger": req.trigger.to_string(),
            "perception": perception_name(&req.perception),
            "record_compression": req.record_compression.to_string(),
            "reregister": req.reregister,
            "mask": req.mask.to_string(),
            "mask_margin_px": req.mask_margin_px,
            "target_model": req.target_model,
            "arm": match &req.target {
                ArmTarget::Stub { faults } => format!(
                    "stub (faults: {:?})",
                    faults.iter().map(ToString::to_string).collect::<Vec<_>>()
                ),
                ArmTarget::Remote { host } => host.clone(),
            },
        })
        .to_string(),
        trajectory_sha256: source.sha256.clone(),
        trajectory_meta: traj.meta.clone().unwrap_or_default(),
        lab_config: req.lab.to_toml(),
        calibration: req.lab.calibration_name(),
        versions,
        scale: Some(scale),
        extra: [
            ("target_model".to_string(), req.target_model.clone()),
            (
                hitl_perception::reregister::METADATA_KEY.to_string(),
                serde_json::json!(req.reregister).to_string(),
            ),
            ("mask_source".to_string(), req.mask.to_string()),
            ("mask_margin_px".to_string(), req.mask_margin_px.to_string()),
        ]
        .into(),
        sun_phase: traj.sun_phase_deg.as_ref().map(|deg| SunPhaseTrack {
            t_s: traj.t.iter().map(|t| t / req.speed_scale).collect(),
            sun_phase_deg: deg.clone(),
        }),
    };
    let config =
        RecorderConfig { compression: req.record_compression, ..RecorderConfig::default() };
    Recorder::spawn_live(path, &meta, config, live)
        .map(Some)
        .map_err(|e| RunError::BadInput(format!("cannot record to {}: {e}", path.display())))
}

/// Start the live view, when asked (`--live`): listening before the arm is connected, so a port
/// in use fails the run (exit 5) before anything moves. Its tap goes to the recorder.
pub(super) fn start_live(
    req: &RunRequest,
    runtime: &tokio::runtime::Runtime,
) -> Result<(Option<LiveServer>, Option<LiveTap>), RunError> {
    let Some(cfg) = req.live else { return Ok((None, None)) };
    if req.record.is_none() {
        return Err(RunError::BadInput(
            "--live needs the run recorded (the recorder feeds it)".into(),
        ));
    }
    let (server, tap) =
        LiveServer::start(cfg, runtime.handle()).map_err(|e| RunError::Device(e.to_string()))?;
    crate::errln!(
        "live view: ws://{} (Foxglove: Open connection, Foxglove WebSocket)",
        server.addr()
    );
    Ok((Some(server), Some(tap)))
}

/// `--perception` as the operator wrote it.
fn perception_name(spec: &BackendSpec) -> String {
    match spec {
        BackendSpec::None => "none".into(),
        BackendSpec::Icp => "icp".into(),
        BackendSpec::Mono => "mono".into(),
        BackendSpec::Onnx(p) => format!("onnx:{}", p.display()),
        BackendSpec::Socket(p) => format!("socket:{}", p.display()),
    }
}

/// After the loop: frames for the last captures may still be on their way; hand them to the
/// intake while they keep coming (until 2 s pass without one), so every capture is recorded or
/// reported. A camera that buffers a backlog (the simulated one's renderer behind a loaded
/// machine: docs/sim-camera.md) delivers it all. It ends once every fired capture has a frame,
/// and after [`LATE_FRAMES_MAX`] at most, so a camera that keeps streaming (left free-running)
/// cannot hold the run open.
pub(super) fn collect_late_frames(camera: &mut RunCamera, intake: &IntakeQueues, fired: u64) {
    let quiet = Duration::from_secs(2);
    let started = Instant::now();
    let mut deadline = started + quiet;
    while Instant::now() < deadline && started.elapsed() < LATE_FRAMES_MAX {
        match camera.poll_frame() {
            Ok(Some(frame)) => {
                deadline = Instant::now() + quiet;
                let delivered = intake.frames_in.fetch_add(1, Ordering::Relaxed) + 1;
                if intake.frames.push(frame).is_err() {
                    intake.frames_lost.fetch_add(1, Ordering::Relaxed);
                }
                if delivered >= fired {
                    break;
                }
            }
            Ok(None) => {
                let delivered = intake.frames_in.load(Ordering::Relaxed);
                if !camera.delivers_frames() || delivered >= fired {
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => break,
        }
    }
}

/// The longest the session waits for late frames after the loop: the simulated camera's whole
/// exposure queue (64) rendered at a loaded machine's pace fits well inside it.
const LATE_FRAMES_MAX: Duration = Duration::from_secs(60);
