//! The run's devices besides the arm: what the operator chose (typed `--camera` / `--light`
//! values), opening them on the run's runtime, and holding them behind one shape for the loop.
//! This is the only part of the controller that names drivers; `src/control` sees hal traits.
//!
//! - [`arm`]: the arm's driver, named for the session;
//! - [`camera`]: `--camera` ([`CameraSpec`]), the stream asked of it, and opening it;
//! - [`light`]: `--light` (the drivers' `LightSpec` registry) and the inputs and trigger lines
//!   that come with a light device;
//! - [`inputs`]: every safety-input source of the run, read together;
//! - [`any`]: the trait objects and adapters that give the loop one type per role;
//! - [`none`]: the deliberately absent devices.

pub mod any;
pub mod arm;
pub mod camera;
pub mod inputs;
pub mod light;
pub mod none;

pub use any::{RunCamera, RunLight, RunTrigger};
pub use camera::{CameraSpec, CameraSpecError};
pub use hitl_drivers::light::LightSpec;
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
    camera::check_trigger_wiring(choice.camera, &choice.light)?;
    let opened = light::open_light(&choice.light, ctx)?;
    let camera = camera::open_camera(choice.camera, &choice.stream, ctx)?;
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
