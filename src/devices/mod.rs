//! The run's devices besides the arm: what the operator chose (typed `--camera` / `--light`
//! values), opening them on the run's runtime, and holding them behind one shape for the loop.
//! This is the only part of the controller that names drivers; `src/control` sees hal traits.
//!
//! - [`arm`]: the arm's driver, named for the session;
//! - [`camera`]: `--camera` ([`CameraSpec`]), the stream asked of it, and opening it;
//! - [`light`]: `--light` (the drivers' `LightSpec` registry) and the inputs and trigger lines
//!   that come with a light device;
//! - [`trigger`]: `--trigger` (the drivers' `TriggerSpec` registry): which device fires the
//!   camera and feeds its e-stop and door to the interlocks;
//! - [`inputs`]: every safety-input source of the run, read together;
//! - [`any`]: the trait objects and adapters that give the loop one type per role;
//! - [`none`]: the deliberately absent devices;
//! - [`pulse`]: a hardware-triggered camera's exposure at the trigger box's pulse;
//! - [`stub`]: the embedded MuJoCo stub (SITL) a run without `--arm` plays on.

pub mod any;
pub mod arm;
pub mod camera;
pub mod inputs;
pub mod light;
pub mod none;
pub mod pulse;
#[cfg(feature = "stub")]
pub mod stub;
pub mod trigger;

pub use any::{RunCamera, RunLight, RunTrigger};
pub use camera::{CameraSpec, CameraSpecError};
pub use hitl_drivers::light::{LightSpec, TriggerSpec};
pub use inputs::RunInputs;

use hitl_hal::{Lifecycle, MonotonicClock, RgbdCamera, StreamConfig};

/// Why a device could not be opened or started.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DeviceError {
    /// The choice cannot work in this run (exit 2).
    #[error("{0}")]
    BadInput(String),
    /// The device is absent or did not answer (exit 5); the message names it.
    #[error("{0}")]
    Failed(String),
}

/// The stub's simulated scene, which the simulated camera, light and inputs share with it.
#[cfg(feature = "stub")]
pub struct SimScene<'a> {
    pub lab_model: &'a hitl_sim_stub::mujoco_plant::LabModel,
    pub arm: &'a hitl_sim_stub::mujoco_plant::SharedArmState,
    pub light: &'a hitl_sim_stub::camera::LightLevel,
    pub inputs: hitl_sim_stub::SimInputsReader,
    /// The simulated camera's noise and depth model.
    pub camera_noise: hitl_sim_stub::camera::NoiseModel,
    /// The simulated camera's lens, which it announces in its intrinsics.
    pub camera_lens: hitl_hal::Distortion,
    /// The simulated camera's captures taken and rendered (a simulated clock waits on them).
    pub render_backlog: &'a hitl_sim_stub::camera::RenderBacklog,
}

/// `--depth-model`: how the simulated camera's depth is degraded (docs/sim-camera.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SimDepthModel {
    /// Depth as rendered, every surface pixel exact: what the README's SITL accuracy figures
    /// were measured with (the default).
    #[default]
    Ideal,
    /// The Orbbec Gemini 305's stereo depth: error k z^2, invalid pixels at edges, in the
    /// projector's and second camera's shadows and at grazing angles, seeded per capture.
    Orbbec,
}

impl std::str::FromStr for SimDepthModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ideal" => Ok(Self::Ideal),
            "orbbec" => Ok(Self::Orbbec),
            other => Err(format!("unknown depth model {other:?} (expected ideal or orbbec)")),
        }
    }
}

impl std::fmt::Display for SimDepthModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Ideal => "ideal",
            Self::Orbbec => "orbbec",
        })
    }
}

/// What opening a device may use: the run's runtime (drivers' I/O tasks live on it for the
/// whole run), the run's clock, and the stub's scene when the run targets the stub.
pub struct OpenContext<'a> {
    pub runtime: &'a tokio::runtime::Handle,
    pub clock: MonotonicClock,
    #[cfg(feature = "stub")]
    pub sim: Option<SimScene<'a>>,
}

impl OpenContext<'_> {
    #[cfg(feature = "stub")]
    fn sim_needed(&self, what: &str) -> Result<&SimScene<'_>, DeviceError> {
        self.sim.as_ref().ok_or_else(|| {
            DeviceError::BadInput(format!("--{what} sim needs the embedded stub (no --arm)"))
        })
    }
}

/// The devices chosen for a run.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceChoice {
    pub camera: CameraSpec,
    pub light: LightSpec,
    /// The device that fires the camera and feeds its inputs (`--trigger`).
    pub trigger: TriggerSpec,
    /// The stream asked of the camera.
    pub stream: StreamConfig,
}

/// The run's devices besides the arm.
pub struct RunDevices {
    pub camera: RunCamera,
    pub light: RunLight,
    pub inputs: RunInputs,
    pub trigger: RunTrigger,
}

/// Open every device chosen; a device that cannot be opened fails the run before anything moves.
pub fn open_devices(
    choice: &DeviceChoice,
    ctx: &OpenContext<'_>,
) -> Result<RunDevices, DeviceError> {
    camera::check_trigger_wiring(choice.camera, &choice.light, &choice.trigger)?;
    let mut opened = light::open_light(&choice.light, ctx)?;
    trigger::open_trigger(&choice.trigger, &choice.light, &mut opened, ctx)?;
    let mut camera = camera::open_camera(choice.camera, &choice.stream, ctx)?;
    if camera::pulse_triggered(choice.camera, &choice.light, &choice.trigger) {
        // The camera exposes at the box's pulse: its frames take that time (mapped onto the
        // host's clock) as their exposure.
        let times = pulse::FireTimes::new();
        let trigger =
            std::mem::replace(&mut opened.trigger.dev, Box::new(any::Kinds::new(none::NoTrigger)));
        opened.trigger.dev = Box::new(pulse::RecordFires { inner: trigger, times: times.clone() });
        let cam = std::mem::replace(&mut camera.dev, Box::new(any::Kinds::new(none::NoCamera)));
        camera.dev = Box::new(pulse::PulseExposure { inner: cam, times });
    }
    #[cfg_attr(not(feature = "stub"), allow(unused_mut))]
    let mut inputs = opened.inputs;
    #[cfg(feature = "stub")]
    if let Some(sim) = &ctx.sim {
        let reader = hitl_sim_stub::SimInputsReader(std::sync::Arc::clone(&sim.inputs.0));
        inputs.add("stub inputs", Box::new(any::Kinds::new(any::Unmanaged(reader))));
    }
    Ok(RunDevices { camera, light: opened.light, inputs, trigger: opened.trigger })
}

impl RunDevices {
    /// Configure and arm the camera, then start every device (hal's `Lifecycle::start`): after
    /// this the devices do their jobs. Called before the arm is enabled; a failure names the
    /// device and nothing has moved.
    pub fn start(&mut self, stream: &StreamConfig) -> Result<(), DeviceError> {
        let failed = |name: &str, step: &str, why: String| {
            DeviceError::Failed(format!("{name}: {step} failed: {why}"))
        };
        let cam = self.camera.name().to_string();
        self.camera.configure(stream).map_err(|k| {
            failed(&cam, "configure", self.camera.fault_text().unwrap_or(k.to_string()))
        })?;
        self.camera.arm_trigger().map_err(|k| {
            failed(&cam, "arm trigger", self.camera.fault_text().unwrap_or(k.to_string()))
        })?;
        self.camera.start().map_err(|k| {
            failed(&cam, "start", self.camera.fault_text().unwrap_or(k.to_string()))
        })?;
        let light = self.light.name().to_string();
        self.light.start().map_err(|k| {
            failed(&light, "start", self.light.fault_text().unwrap_or(k.to_string()))
        })?;
        let trigger = self.trigger.name().to_string();
        self.trigger.start().map_err(|k| {
            failed(&trigger, "start", self.trigger.fault_text().unwrap_or(k.to_string()))
        })?;
        self.inputs.start().map_err(|k| {
            DeviceError::Failed(format!(
                "safety inputs: start failed: {}",
                self.inputs.fault_text().unwrap_or(k.to_string())
            ))
        })
    }

    /// Stop every device (hal's `Lifecycle::stop`), after the loop; each is stopped even when
    /// another fails. Returns what failed to stop, in words.
    pub fn stop(&mut self) -> Vec<String> {
        let results = [
            (self.camera.stop(), self.camera.name()),
            (self.light.stop(), self.light.name()),
            (self.trigger.stop(), self.trigger.name()),
            (self.inputs.stop(), "safety inputs"),
        ];
        results
            .into_iter()
            .filter_map(|(r, name)| r.err().map(|k| format!("{name}: stop failed ({k})")))
            .collect()
    }

    /// The devices that failed during the run and why, in words (after the loop).
    pub fn faults(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut add = |name: &str, why: Option<String>| {
            if let Some(why) = why {
                out.push(format!("{name}: {why}"));
            }
        };
        add(self.camera.name(), self.camera.fault_text());
        add(self.light.name(), self.light.fault_text());
        add(self.trigger.name(), self.trigger.fault_text());
        if let Some(why) = self.inputs.fault_text() {
            out.push(format!("safety inputs from {why}"));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::any::{Kinds, Unmanaged};
    use super::*;
    use hitl_hal::{CaptureRequest, ErrorKind, ErrorType, Intrinsics, RgbdFrame};
    use std::sync::{Arc, Mutex};

    type Calls = Arc<Mutex<Vec<&'static str>>>;

    /// A camera that, like the Orbbec driver, refuses to arm its trigger before it is configured.
    struct Scripted {
        calls: Calls,
        configured: bool,
        configure_fails: bool,
    }

    impl Scripted {
        fn log(&self, call: &'static str) {
            self.calls.lock().unwrap_or_else(|e| e.into_inner()).push(call);
        }
    }

    impl ErrorType for Scripted {
        type Error = ErrorKind;
    }

    impl RgbdCamera for Scripted {
        fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
            self.log("configure");
            if self.configure_fails {
                return Err(ErrorKind::NotFound);
            }
            self.configured = true;
            Ok(config.intrinsics)
        }
        fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
            self.log("arm_trigger");
            if self.configured {
                Ok(())
            } else {
                Err(ErrorKind::InvalidRequest)
            }
        }
        fn trigger(&mut self, _request: CaptureRequest) -> Result<(), ErrorKind> {
            Ok(())
        }
        fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
            Ok(None)
        }
    }

    fn start_with(configure_fails: bool) -> (Result<(), DeviceError>, Vec<&'static str>) {
        let calls = Calls::default();
        let cam = Scripted { calls: Arc::clone(&calls), configured: false, configure_fails };
        let runtime =
            tokio::runtime::Builder::new_current_thread().enable_all().build().expect("runtime");
        let ctx = OpenContext {
            runtime: runtime.handle(),
            clock: MonotonicClock::new(),
            #[cfg(feature = "stub")]
            sim: None,
        };
        let opened = light::open_light(&LightSpec::None, &ctx).expect("no light opens");
        let mut devices = RunDevices {
            camera: RunCamera {
                dev: Box::new(Kinds::new(Unmanaged(cam))),
                name: "scripted camera".into(),
                delivers_frames: true,
            },
            light: opened.light,
            inputs: opened.inputs,
            trigger: opened.trigger,
        };
        let stream = StreamConfig {
            intrinsics: Intrinsics {
                width: 64,
                height: 48,
                fx: 40.0,
                fy: 40.0,
                cx: 32.0,
                cy: 24.0,
                distortion: Default::default(),
            },
            mask: false,
        };
        let started = devices.start(&stream);
        let calls = calls.lock().unwrap_or_else(|e| e.into_inner()).clone();
        (started, calls)
    }

    /// The Orbbec path could never start because nothing configured the camera before arming
    /// it: every camera is configured, then armed, before the arm is enabled.
    #[test]
    fn a_camera_is_configured_before_its_trigger_is_armed() {
        let (started, calls) = start_with(false);
        assert_eq!(started, Ok(()));
        assert_eq!(calls, ["configure", "arm_trigger"]);
    }

    #[test]
    fn a_camera_that_cannot_be_configured_is_named_and_never_armed() {
        let (started, calls) = start_with(true);
        let Err(DeviceError::Failed(why)) = started else { panic!("{started:?}") };
        assert!(why.contains("scripted camera: configure failed"), "{why}");
        assert_eq!(calls, ["configure"]);
    }
}
