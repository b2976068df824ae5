//! `hitl probe` for Orbbec cameras: what every connected camera is and offers, and the sync
//! configuration it holds now (with a crashed run's state file, if one is left), opening nothing
//! for streaming, changing nothing and moving nothing.

use std::fmt::Write as _;
use std::path::Path;

use hitl_hal::ErrorKind;

use super::backend::{Setting, Stream};
use super::error::OrbbecError;
use super::ffi::{
    Device, Pipeline, ProfileDesc, OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT, OB_SENSOR_COLOR,
    OB_SENSOR_DEPTH,
};
use super::marker::{self, Leftover};
use super::profiles::VideoProfile;
use super::sdk::{identity_of, list_profiles, load, property_id, sync_from_ffi};
use super::sync::{documented, mode_names, SyncConfig};

/// The firmware from which the Gemini 305 offers `OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT`.
pub const SYNC_VOLTAGE_FIRMWARE: (u32, u32, u32) = (1, 0, 76);

/// Lens distortion as the SDK reports it (`ob_camera_distortion`); printed for commissioning,
/// not used by the driver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distortion {
    pub k: [f32; 6],
    pub p1: f32,
    pub p2: f32,
    /// `ob_camera_distortion_model`.
    pub model: i32,
}

impl Distortion {
    pub fn model_name(&self) -> &'static str {
        match self.model {
            0 => "none",
            1 => "modified Brown-Conrady",
            2 => "inverse Brown-Conrady",
            3 => "Brown-Conrady",
            4 => "Brown-Conrady k6",
            5 => "Kannala-Brandt 4",
            _ => "unknown model",
        }
    }
}

/// One stream profile's intrinsics and distortion as the SDK reports them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lens {
    pub profile: VideoProfile,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub distortion: Option<Distortion>,
}

/// `X.Y.Z` out of a firmware text such as "1.0.80" or "RD1.0.80".
pub fn firmware_version(text: &str) -> Option<(u32, u32, u32)> {
    let start = text.find(|c: char| c.is_ascii_digit())?;
    let mut parts = text[start..]
        .split(|c: char| !c.is_ascii_digit())
        .filter(|p| !p.is_empty())
        .map(|p| p.parse::<u32>().ok());
    Some((parts.next()??, parts.next()??, parts.next()??))
}

/// One connected Orbbec camera as the SDK and this driver see it.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    pub name: String,
    pub serial: String,
    /// USB product id (Gemini 305: 0x0840/0x0841, Gemini 305g: 0x0842).
    pub product_id: u16,
    pub firmware: String,
    pub sdk_version: String,
    pub color_profiles: Vec<VideoProfile>,
    pub depth_profiles: Vec<VideoProfile>,
    /// Sync modes (`OB_MULTI_DEVICE_SYNC_MODE_*` bits) Orbbec documents for this model; None for
    /// a model this driver has no documentation for (it then refuses to trigger it).
    pub documented_sync_modes: Option<u16>,
    /// Sync modes the SDK advertises for the device (may list more than the documentation).
    pub advertised_sync_modes: u16,
    /// The sync configuration the camera holds now (None: the SDK would not say, with why).
    pub sync: Result<SyncConfig, String>,
    /// A state file of a run that did not write this camera's configuration back.
    pub leftover: Option<Leftover>,
    /// Whether the camera offers writing the sync voltage level, and its value now if readable.
    pub sync_voltage_settable: bool,
    pub sync_voltage_level: Option<i32>,
    /// Intrinsics and distortion of each colour and depth size (first profile of each size).
    pub lenses: Vec<Lens>,
}

impl CameraInfo {
    /// Whether the firmware is new enough for the sync voltage setting (None: unparsable).
    pub fn firmware_has_sync_voltage(&self) -> Option<bool> {
        firmware_version(&self.firmware).map(|v| v >= SYNC_VOLTAGE_FIRMWARE)
    }

    /// Everything `hitl probe` prints: [`Self::describe`], then the sync configuration found,
    /// the sync voltage, a crashed run's leftover, and each size's intrinsics and distortion.
    pub fn report(&self) -> String {
        let mut s = self.describe();
        let (a, b, c) = SYNC_VOLTAGE_FIRMWARE;
        let _ = write!(
            s,
            "\n  firmware {} for the sync voltage setting (needs >= {a}.{b}.{c}); the camera {} \
             it{}",
            match self.firmware_has_sync_voltage() {
                Some(true) => "new enough",
                Some(false) => "too old",
                None => "of unknown version",
            },
            if self.sync_voltage_settable { "offers" } else { "does not offer" },
            match self.sync_voltage_level {
                Some(v) => format!(" (level now {v})"),
                None => String::new(),
            }
        );
        match &self.sync {
            Ok(sync) => {
                let _ = write!(s, "\n  sync mode found: {sync}");
                if sync.is_triggered() && self.leftover.is_none() {
                    s.push_str(
                        "\n  note: the camera waits for triggers: other tools get no frames from \
                         it until it is set back to free-run",
                    );
                }
            }
            Err(e) => {
                let _ = write!(s, "\n  sync mode found: cannot read ({e})");
            }
        }
        if let Some(l) = &self.leftover {
            let _ = write!(s, "\n  LEFTOVER: {}; the next hitl run writes it back", l.describe());
        }
        for l in &self.lenses {
            let _ = write!(
                s,
                "\n  intrinsics {}x{} {}: fx {:.3} fy {:.3} cx {:.3} cy {:.3}",
                l.profile.width,
                l.profile.height,
                if l.profile.format == super::frame::FORMAT_Y16 { "depth" } else { "colour" },
                l.fx,
                l.fy,
                l.cx,
                l.cy
            );
            if let Some(d) = &l.distortion {
                let _ = write!(
                    s,
                    "; distortion {} k {:?} p1 {} p2 {} (the colour lens is what runs project through)",
                    d.model_name(),
                    d.k,
                    d.p1,
                    d.p2
                );
            }
        }
        s
    }

    /// A few lines for the operator.
    pub fn describe(&self) -> String {
        let documented = match self.documented_sync_modes {
            Some(bits) => mode_names(bits),
            None => "unknown model (not triggered by hitl)".into(),
        };
        let list =
            |p: &[VideoProfile]| p.iter().map(|p| p.to_string()).collect::<Vec<_>>().join(", ");
        format!(
            "{} serial {} pid {:#06x} firmware {} (Orbbec SDK {})\n  sync documented: {documented}\n  \
             sync advertised by the SDK: {}\n  colour: {}\n  depth: {}",
            self.name,
            self.serial,
            self.product_id,
            self.firmware,
            self.sdk_version,
            mode_names(self.advertised_sync_modes),
            list(&self.color_profiles),
            list(&self.depth_profiles)
        )
    }
}

/// Every connected Orbbec camera, through the SDK library at `library` (usually
/// [`super::OrbbecOptions::default_library`]), with the state files in the default state
/// directory. No camera: an empty list. A missing or broken library: `NotFound` naming its path.
pub fn probe(library: &Path) -> Result<Vec<CameraInfo>, OrbbecError> {
    probe_with(library, marker::default_state_dir().as_deref())
}

/// The intrinsics and distortion of the first profile of each size of `sensor`'s `profiles`.
fn lenses(pipeline: &Pipeline, sensor: i32, profiles: &[VideoProfile]) -> Vec<Lens> {
    let mut seen = Vec::new();
    let mut out = Vec::new();
    for p in profiles {
        if seen.contains(&(p.width, p.height)) {
            continue;
        }
        seen.push((p.width, p.height));
        let desc = ProfileDesc { width: p.width, height: p.height, format: p.format, fps: p.fps };
        let Ok(found) = pipeline.video_profile(sensor, desc) else { continue };
        let Ok(k) = found.intrinsic() else { continue };
        let distortion = found.distortion().ok().map(|d| Distortion {
            k: d.k,
            p1: d.p1,
            p2: d.p2,
            model: d.model,
        });
        out.push(Lens { profile: *p, fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy, distortion });
    }
    out
}

fn sync_voltage(device: &Device) -> (bool, Option<i32>) {
    let id = property_id(Setting::SyncVoltageLevel);
    debug_assert_eq!(id, OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT);
    let settable = device.property_writable(id).unwrap_or(false);
    let level = match device.property_readable(id) {
        Ok(true) => device.int_property(id).ok(),
        _ => None,
    };
    (settable, level)
}

/// [`probe`] with the state files under `state_dir` (None: none looked for).
pub fn probe_with(
    library: &Path,
    state_dir: Option<&Path>,
) -> Result<Vec<CameraInfo>, OrbbecError> {
    let loaded = load(library)?;
    let list = loaded.context.devices().map_err(|e| OrbbecError::sdk("listing devices", &e))?;
    let count = list.count().map_err(|e| OrbbecError::sdk("counting devices", &e))?;
    let mut out = Vec::new();
    for i in 0..count {
        let device =
            list.device(i).map_err(|e| OrbbecError::sdk("opening the Orbbec camera", &e))?;
        let id = identity_of(&device, &loaded.version)?;
        let advertised_sync_modes =
            device.sync_modes().map_err(|e| OrbbecError::sdk("reading sync modes", &e))?;
        let pipeline =
            Pipeline::new(&device).map_err(|e| OrbbecError::sdk("creating the pipeline", &e))?;
        let color_profiles = list_profiles(&pipeline, Stream::Color)?;
        let depth_profiles = list_profiles(&pipeline, Stream::Depth)?;
        let mut found_lenses = lenses(&pipeline, OB_SENSOR_COLOR, &color_profiles);
        found_lenses.extend(lenses(&pipeline, OB_SENSOR_DEPTH, &depth_profiles));
        drop(pipeline);
        let sync = device
            .sync_config()
            .map_err(|e| e.to_string())
            .and_then(|c| sync_from_ffi(&c).map_err(|e| e.message().to_string()));
        let leftover = state_dir
            .map(|d| marker::read(&marker::marker_path(d, &id.serial)))
            .transpose()
            .map_err(|e| OrbbecError::new(ErrorKind::Other, e))?
            .flatten();
        let (sync_voltage_settable, sync_voltage_level) = sync_voltage(&device);
        out.push(CameraInfo {
            documented_sync_modes: documented(id.product_id).map(|m| m.sync_modes),
            name: id.name,
            serial: id.serial,
            product_id: id.product_id,
            firmware: id.firmware,
            sdk_version: id.sdk_version,
            color_profiles,
            depth_profiles,
            advertised_sync_modes,
            sync,
            leftover,
            sync_voltage_settable,
            sync_voltage_level,
            lenses: found_lenses,
        });
    }
    if out.len() != usize::try_from(count).unwrap_or(usize::MAX) {
        return Err(OrbbecError::new(ErrorKind::Other, "Orbbec camera list changed while probing"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn firmware_versions_are_read_and_compared() {
        assert_eq!(firmware_version("1.0.80"), Some((1, 0, 80)));
        assert_eq!(firmware_version("RD1.0.76"), Some((1, 0, 76)));
        assert_eq!(firmware_version("v1.2"), None);
        assert!(firmware_version("1.0.75").expect("parsed") < SYNC_VOLTAGE_FIRMWARE);
        assert!(firmware_version("1.1.0").expect("parsed") >= SYNC_VOLTAGE_FIRMWARE);
    }
}
