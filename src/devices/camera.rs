//! `--camera sim|orbbec[:hardware|:software]|none`: the choice, the stream the run asks of the camera, and the one
//! place a camera kind is opened (a new kind is its driver plus one variant and one arm here).

use super::any::{Kinds, RunCamera, Unmanaged};
use super::none::NoCamera;
use super::{DeviceError, OpenContext};
use hitl_drivers::light::{LightSpec, TriggerSpec};
use hitl_drivers::orbbec::TriggerChoice;
use hitl_hal::{Intrinsics, StreamConfig};
use std::fmt;
use std::str::FromStr;

/// The camera chosen on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraSpec {
    /// The stub's simulated RGB-D camera (needs the embedded stub), drawn by MuJoCo's own
    /// OpenGL renderer on an offscreen EGL device (Mesa's software one on a machine without a
    /// GPU); without a usable device the run stops before motion (exit 5) naming the missing
    /// package. The stub's ray cast is not offered here: it is about 11x slower, flat-shaded, and
    /// kept only for `hitl bench render` and as the renderer's test reference.
    Sim,
    /// An Orbbec RGB-D camera through the Orbbec SDK, triggered as chosen: `orbbec` (hardware
    /// where the model documents it, which every supported model does), `orbbec:hardware`, or
    /// `orbbec:software` (only models documented for it: the Gemini 305, not the 305g).
    Orbbec(TriggerChoice),
    /// No camera: captures are recorded as fired and no frame comes.
    None,
}

/// Why a `--camera` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not a camera: expected sim, orbbec, orbbec:hardware, orbbec:software or none")]
pub struct CameraSpecError(pub String);

impl FromStr for CameraSpec {
    type Err = CameraSpecError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "sim" => Ok(CameraSpec::Sim),
            "orbbec" => Ok(CameraSpec::Orbbec(TriggerChoice::Auto)),
            "orbbec:hardware" => Ok(CameraSpec::Orbbec(TriggerChoice::Hardware)),
            "orbbec:software" => Ok(CameraSpec::Orbbec(TriggerChoice::Software)),
            "none" => Ok(CameraSpec::None),
            other => Err(CameraSpecError(other.to_string())),
        }
    }
}

impl fmt::Display for CameraSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CameraSpec::Sim => "sim",
            CameraSpec::Orbbec(TriggerChoice::Auto) => "orbbec",
            CameraSpec::Orbbec(TriggerChoice::Hardware) => "orbbec:hardware",
            CameraSpec::Orbbec(TriggerChoice::Software) => "orbbec:software",
            CameraSpec::None => "none",
        })
    }
}

/// The Orbbec Gemini-class stream (1280x800, f = 640 px), for builds without the stub's presets.
#[cfg(not(feature = "stub"))]
const ORBBEC_STREAM: Intrinsics =
    Intrinsics { width: 1280, height: 800, fx: 640.0, fy: 640.0, cx: 640.0, cy: 400.0 };

/// The stream the run asks of `spec`: the `--camera-preset` intrinsics (scaled to
/// `--camera-size`), and a target mask where the camera can give one (only the simulated one).
pub fn stream_config(
    spec: CameraSpec,
    preset: &str,
    size: Option<(u32, u32)>,
) -> Result<StreamConfig, DeviceError> {
    let intrinsics = preset_intrinsics(preset, size)?;
    Ok(StreamConfig { intrinsics, mask: spec == CameraSpec::Sim })
}

#[cfg(feature = "stub")]
fn preset_intrinsics(preset: &str, size: Option<(u32, u32)>) -> Result<Intrinsics, DeviceError> {
    use hitl_sim_stub::camera::Preset;
    let p = Preset::from_name(preset).ok_or_else(|| {
        DeviceError::BadInput(format!("--camera-preset {preset}: expected nfov, wfov or orbbec"))
    })?;
    Ok(match size {
        Some((w, h)) => p.at(w, h),
        None => p.intrinsics(),
    })
}

#[cfg(not(feature = "stub"))]
fn preset_intrinsics(preset: &str, size: Option<(u32, u32)>) -> Result<Intrinsics, DeviceError> {
    if preset != "orbbec" || size.is_some() {
        return Err(DeviceError::BadInput(
            "--camera-preset and --camera-size need the stub feature (the presets live there)"
                .into(),
        ));
    }
    Ok(ORBBEC_STREAM)
}

/// The fastest capture rate the camera `spec` follows, Hz, with why, for the preflight's
/// capture-rate rule; `None` for a camera without such a limit (the stub's renders every
/// capture; none captures nothing). The Orbbec SDK needs trigger rate x frames per trigger below
/// the stream's frame rate, and its own example keeps the trigger at most at half of it: half
/// the frame rate the driver asks for first (its profiles' preferred rate, 30 fps).
pub fn capture_limit(spec: CameraSpec) -> Option<(f64, String)> {
    match spec {
        CameraSpec::Orbbec(_) => {
            let fps = f64::from(hitl_drivers::orbbec::profiles::PREFERRED_FPS[0]);
            Some((fps / 2.0, format!("camera {spec} follows (half its {fps:.0} fps stream)")))
        }
        _ => None,
    }
}

/// Refuse a camera that cannot be triggered with the devices chosen, before anything opens: a
/// hardware-triggered Orbbec camera (the default) takes its frames on the trigger box's camera
/// line, so without a trigger box (`--trigger trigger:DEV`, or `--light trigger:DEV` taking both
/// roles) every capture would be missed and the camera would fault mid-run.
pub fn check_trigger_wiring(
    camera: CameraSpec,
    light: &LightSpec,
    trigger: &TriggerSpec,
) -> Result<(), DeviceError> {
    let has_box = trigger.port().is_some() || matches!(light, LightSpec::Trigger { .. });
    match camera {
        CameraSpec::Orbbec(TriggerChoice::Software) => Ok(()),
        CameraSpec::Orbbec(_) if !has_box => Err(DeviceError::BadInput(format!(
            "--camera {camera} is hardware-triggered: its sync input is driven by the trigger \
             box's camera line, so name the box with --trigger trigger:DEV (docs/devices.md), or \
             use --camera orbbec:software on a model documented for software triggering \
             (Gemini 305)"
        ))),
        _ => Ok(()),
    }
}

/// Open the camera `spec` names (not yet configured: the session configures and arms it).
pub fn open_camera(
    spec: CameraSpec,
    stream: &StreamConfig,
    ctx: &OpenContext<'_>,
) -> Result<RunCamera, DeviceError> {
    let _ = stream;
    Ok(match spec {
        CameraSpec::None => RunCamera {
            dev: Box::new(Kinds::new(NoCamera)),
            name: "no camera".into(),
            delivers_frames: false,
        },
        #[cfg(feature = "stub")]
        CameraSpec::Sim => {
            use hitl_sim_stub::camera::{SimCamera, SimCameraConfig};
            let sim = ctx.sim_needed("camera")?;
            let config = SimCameraConfig {
                intrinsics: stream.intrinsics,
                clock: ctx.clock,
                noise: sim.camera_noise,
                ..Default::default()
            };
            let cam =
                SimCamera::new(sim.lab_model.clone(), sim.arm.clone(), sim.light.clone(), config)
                    .map_err(|e| DeviceError::Failed(e.to_string()))?;
            RunCamera {
                dev: Box::new(Kinds::new(Unmanaged(cam))),
                name: "simulated camera".into(),
                delivers_frames: true,
            }
        }
        #[cfg(not(feature = "stub"))]
        CameraSpec::Sim => {
            return Err(DeviceError::BadInput("--camera sim needs the stub feature".into()))
        }
        CameraSpec::Orbbec(trigger) => {
            use hitl_drivers::orbbec::{OrbbecCamera, OrbbecOptions};
            let options = OrbbecOptions { clock: ctx.clock, trigger, ..Default::default() };
            let cam = OrbbecCamera::open(options)
                .map_err(|e| DeviceError::Failed(format!("Orbbec camera: {e}")))?;
            RunCamera {
                dev: Box::new(Kinds::new(Unmanaged(cam))),
                name: "Orbbec camera".into(),
                delivers_frames: true,
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbbec_trigger_choices_parse_and_print_back() {
        for text in ["orbbec", "orbbec:hardware", "orbbec:software", "sim", "none"] {
            let spec: CameraSpec = text.parse().expect(text);
            assert_eq!(spec.to_string(), text);
        }
        assert_eq!("orbbec".parse(), Ok(CameraSpec::Orbbec(TriggerChoice::Auto)));
        assert!("orbbec:hw".parse::<CameraSpec>().is_err());
    }

    #[test]
    fn a_hardware_triggered_orbbec_needs_the_trigger_box() {
        let none = LightSpec::None;
        let no_box = TriggerSpec::None;
        let tb_light = LightSpec::Trigger { port: "/dev/ttyACM0".into() };
        let tb = TriggerSpec::Box { port: "/dev/ttyACM0".into() };
        let dmx: LightSpec = "dmx:/dev/ttyUSB0".parse().expect("dmx");
        let auto = CameraSpec::Orbbec(TriggerChoice::Auto);
        let hw = CameraSpec::Orbbec(TriggerChoice::Hardware);
        let sw = CameraSpec::Orbbec(TriggerChoice::Software);
        assert!(
            matches!(check_trigger_wiring(auto, &none, &no_box), Err(DeviceError::BadInput(m)) if m.contains("--trigger trigger:DEV"))
        );
        assert!(check_trigger_wiring(hw, &LightSpec::Sim, &no_box).is_err());
        assert!(check_trigger_wiring(hw, &dmx, &no_box).is_err());
        // The box named as the trigger, the light elsewhere: a DMX lab triggers its camera.
        assert_eq!(check_trigger_wiring(hw, &dmx, &tb), Ok(()));
        // The old spelling: the box as the light takes both roles.
        assert_eq!(check_trigger_wiring(auto, &tb_light, &no_box), Ok(()));
        assert_eq!(check_trigger_wiring(hw, &tb_light, &no_box), Ok(()));
        assert_eq!(check_trigger_wiring(sw, &none, &no_box), Ok(()));
        assert_eq!(check_trigger_wiring(CameraSpec::None, &none, &no_box), Ok(()));
    }
}
