//! The run's devices besides the arm (camera, light, inputs), the target scene the camera looks
//! at, the recorder, and the frames still on their way after the loop.

#[cfg(feature = "stub")]
use super::arm_link::EmbeddedStub;
use super::{ArmTarget, RunError, RunRequest};
#[cfg(feature = "stub")]
use crate::capture::sim_light::SimLight;
use crate::capture::sink::IntakeQueues;
use crate::devices::any::{RunCamera, RunLight};
use crate::devices::inputs::RunInputs;
use crate::devices::none::{NoCamera, NoInputs, NoLight};
use hitl_drivers::light::{LightSpec, SerialLight};
use hitl_hal::MonotonicClock;
use hitl_hal::RgbdCamera as _;
use hitl_record::{
    Recorder, RecorderConfig, RecorderHandle, RunMetadata, SunPhaseTrack, Telemetry,
};
use hitl_trajectories::Trajectory;
use sha2::Digest as _;
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

/// A perception pose (4x4 matrix) as the recorder's pose.
pub(super) fn record_pose(m: &nalgebra::Matrix4<f64>) -> hitl_record::Pose {
    let rows: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
    hitl_record::Pose::from_matrix(&rows)
}

/// The run's devices besides the arm, opened before anything moves.
pub(super) struct RunDevices {
    pub(super) camera: RunCamera,
    pub(super) light: RunLight,
    pub(super) inputs: RunInputs,
}

/// Open camera, light and inputs as asked; a device that cannot be opened fails the run (exit 5)
/// before the arm is enabled.
pub(super) fn open_devices(
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
pub(super) fn start_recorder(
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
            "record_compression": req.record_compression.to_string(),
            "reregister": req.reregister,
            "target_model": req.target_model,
            "arm": match &req.target { ArmTarget::Stub { faults } => format!("stub (faults: {faults:?})"), ArmTarget::Remote { host } => host.clone() },
        })
        .to_string(),
        trajectory_sha256: sha.iter().map(|b| format!("{b:02x}")).collect(),
        trajectory_meta: traj.meta.clone().unwrap_or_default(),
        lab_config: req.lab.to_toml(),
        versions,
        scale: Some(scale),
        extra: [
            ("target_model".to_string(), req.target_model.clone()),
            (
                hitl_perception::reregister::METADATA_KEY.to_string(),
                serde_json::json!(req.reregister).to_string(),
            ),
        ]
        .into(),
        sun_phase: traj.sun_phase_deg.as_ref().map(|deg| SunPhaseTrack {
            t_s: traj.t.iter().map(|t| t / req.speed_scale).collect(),
            sun_phase_deg: deg.clone(),
        }),
    };
    let config =
        RecorderConfig { compression: req.record_compression, ..RecorderConfig::default() };
    Recorder::spawn_with(path, &meta, config)
        .map(Some)
        .map_err(|e| RunError::BadInput(format!("cannot record to {}: {e}", path.display())))
}

/// After the loop: frames for the last captures may still be on their way; hand them to the
/// intake (up to 2 s), so every capture is recorded or reported.
pub(super) fn collect_late_frames(camera: &mut RunCamera, intake: &IntakeQueues, fired: u64) {
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
