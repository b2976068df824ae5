//! `--camera sim|orbbec[:hardware|:software][@SERIAL]|none`: the choice, the stream the run asks
//! of the camera, and the one place a camera kind is opened (a new kind is its driver plus one
//! variant and one arm here).

#[cfg(feature = "stub")]
use super::any::Unmanaged;
use super::any::{Kinds, RunCamera};
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
    /// `orbbec:software` (only models documented for it: the Gemini 305, not the 305g); with
    /// `@SERIAL`, the camera with that serial number (needed when several are connected).
    Orbbec(OrbbecSpec),
    /// No camera: captures are recorded as fired and no frame comes.
    None,
}

/// Which Orbbec camera and how it is triggered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OrbbecSpec {
    pub trigger: TriggerChoice,
    pub serial: Option<CameraSerial>,
}

impl OrbbecSpec {
    pub fn new(trigger: TriggerChoice) -> Self {
        Self { trigger, serial: None }
    }
}

/// A camera's serial number as `--camera orbbec@SERIAL` names it: 1 to 32 letters, digits, `-`
/// or `_` (Orbbec's are 12, e.g. CP1E54200057), kept inline so the choice stays `Copy`.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct CameraSerial {
    len: u8,
    bytes: [u8; 32],
}

impl CameraSerial {
    pub fn as_str(&self) -> &str {
        // Only ASCII is ever stored (checked by `parse`).
        std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or("")
    }

    fn parse(s: &str) -> Option<Self> {
        let ok = |c: u8| c.is_ascii_alphanumeric() || c == b'-' || c == b'_';
        if s.is_empty() || s.len() > 32 || !s.bytes().all(ok) {
            return None;
        }
        let mut bytes = [0u8; 32];
        bytes[..s.len()].copy_from_slice(s.as_bytes());
        Some(Self { len: u8::try_from(s.len()).ok()?, bytes })
    }
}

impl fmt::Debug for CameraSerial {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl fmt::Display for CameraSerial {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a `--camera` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{0:?} is not a camera: expected sim, orbbec, orbbec:hardware, orbbec:software (each may end \
     in @SERIAL, 1-32 letters, digits, - or _) or none"
)]
pub struct CameraSpecError(pub String);

impl FromStr for CameraSpec {
    type Err = CameraSpecError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || CameraSpecError(s.to_string());
        let (kind, serial) = match s.split_once('@') {
            Some((k, sn)) => (k, Some(CameraSerial::parse(sn).ok_or_else(bad)?)),
            None => (s, None),
        };
        let trigger = match kind {
            "sim" | "none" if serial.is_some() => return Err(bad()),
            "sim" => return Ok(CameraSpec::Sim),
            "none" => return Ok(CameraSpec::None),
            "orbbec" => TriggerChoice::Auto,
            "orbbec:hardware" => TriggerChoice::Hardware,
            "orbbec:software" => TriggerChoice::Software,
            _ => return Err(bad()),
        };
        Ok(CameraSpec::Orbbec(OrbbecSpec { trigger, serial }))
    }
}

impl fmt::Display for CameraSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let o = match self {
            CameraSpec::Sim => return f.write_str("sim"),
            CameraSpec::None => return f.write_str("none"),
            CameraSpec::Orbbec(o) => o,
        };
        f.write_str(match o.trigger {
            TriggerChoice::Auto => "orbbec",
            TriggerChoice::Hardware => "orbbec:hardware",
            TriggerChoice::Software => "orbbec:software",
        })?;
        match &o.serial {
            Some(sn) => write!(f, "@{sn}"),
            None => Ok(()),
        }
    }
}

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
    Ok(hitl_drivers::orbbec::profiles::GEMINI_STREAM)
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
        CameraSpec::Orbbec(OrbbecSpec { trigger: TriggerChoice::Software, .. }) => Ok(()),
        CameraSpec::Orbbec(_) if !has_box => Err(DeviceError::BadInput(format!(
            "--camera {camera} is hardware-triggered: its sync input is driven by the trigger \
             box's camera line, so name the box with --trigger trigger:DEV (docs/devices.md), or \
             use --camera orbbec:software on a model documented for software triggering \
             (Gemini 305)"
        ))),
        _ => Ok(()),
    }
}

/// Whether `camera` is fired by the trigger box's camera line with the devices chosen (a
/// hardware-triggered Orbbec camera, which [`check_trigger_wiring`] has given a box): its frames'
/// exposure is the box's pulse (`super::pulse`). `orbbec` (auto) counts: hardware triggering is
/// its choice on every supported model (a camera whose firmware does not offer it falls back to
/// software triggering, and its frames would then carry the pulse's time although the SDK
/// triggered them: docs/devices.md).
pub fn pulse_triggered(camera: CameraSpec, light: &LightSpec, trigger: &TriggerSpec) -> bool {
    let has_box = trigger.port().is_some() || matches!(light, LightSpec::Trigger { .. });
    has_box
        && matches!(
            camera,
            CameraSpec::Orbbec(OrbbecSpec {
                trigger: TriggerChoice::Hardware | TriggerChoice::Auto,
                ..
            })
        )
}

/// Open the Orbbec camera `o` names, saying what it held when that needs saying (a crashed run's
/// configuration, a camera left waiting for triggers). Several cameras and none named is bad
/// input (exit 2, listing them); no camera, or none with that serial, is a device failure.
pub fn open_orbbec(
    o: OrbbecSpec,
    clock: hitl_hal::MonotonicClock,
) -> Result<hitl_drivers::orbbec::OrbbecCamera, DeviceError> {
    use hitl_drivers::orbbec::{OrbbecCamera, OrbbecOptions};
    use hitl_hal::{Error as _, ErrorKind};
    let options = OrbbecOptions {
        clock,
        trigger: o.trigger,
        serial: o.serial.map(|s| s.to_string()),
        ..Default::default()
    };
    let cam = OrbbecCamera::open(options).map_err(|e| match e.kind() {
        ErrorKind::InvalidRequest => DeviceError::BadInput(format!("--camera: {}", e.message())),
        _ => DeviceError::Failed(format!("Orbbec camera: {e}")),
    })?;
    if let Some(warning) = cam.found().warning() {
        crate::errln!("warning: Orbbec camera {}: {warning}", cam.info().serial);
    }
    Ok(cam)
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
                lens: sim.camera_lens,
                clock: ctx.clock.clone(),
                noise: sim.camera_noise,
                backlog: sim.render_backlog.clone(),
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
        CameraSpec::Orbbec(o) => {
            let cam = open_orbbec(o, ctx.clock.clone())?;
            let name = format!("Orbbec camera {}", cam.info().serial);
            // Its lifecycle's stop writes the camera's configuration back (so does dropping it).
            RunCamera { dev: Box::new(Kinds::new(cam)), name, delivers_frames: true }
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
        assert_eq!("orbbec".parse(), Ok(CameraSpec::Orbbec(OrbbecSpec::new(TriggerChoice::Auto))));
        assert!("orbbec:hw".parse::<CameraSpec>().is_err());
    }

    #[test]
    fn a_camera_is_named_by_its_serial_number() {
        for text in ["orbbec@CP1E54200057", "orbbec:software@cp-1_2", "orbbec:hardware@X"] {
            let spec: CameraSpec = text.parse().expect(text);
            assert_eq!(spec.to_string(), text);
        }
        let Ok(CameraSpec::Orbbec(o)) = "orbbec:software@CP1".parse() else { panic!("parses") };
        assert_eq!(
            (o.trigger, o.serial.map(|s| s.to_string())),
            (TriggerChoice::Software, Some("CP1".into()))
        );
        for bad in
            ["orbbec@", "orbbec@a b", "sim@CP1", "none@X", &format!("orbbec@{}", "A".repeat(33))]
        {
            assert!(bad.parse::<CameraSpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn a_hardware_triggered_orbbec_needs_the_trigger_box() {
        let none = LightSpec::None;
        let no_box = TriggerSpec::None;
        let tb_light = LightSpec::Trigger { port: "/dev/ttyACM0".into() };
        let tb = TriggerSpec::Box { port: "/dev/ttyACM0".into() };
        let dmx: LightSpec = "dmx:/dev/ttyUSB0".parse().expect("dmx");
        let auto = CameraSpec::Orbbec(OrbbecSpec::new(TriggerChoice::Auto));
        let hw = CameraSpec::Orbbec(OrbbecSpec::new(TriggerChoice::Hardware));
        let sw = CameraSpec::Orbbec(OrbbecSpec::new(TriggerChoice::Software));
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
