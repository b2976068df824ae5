//! `hitl probe` for Orbbec cameras: what every connected camera is and offers, opening nothing
//! for streaming and moving nothing.

use std::path::Path;

use hitl_hal::ErrorKind;

use super::backend::Stream;
use super::error::OrbbecError;
use super::ffi::Pipeline;
use super::profiles::VideoProfile;
use super::sdk::{identity_of, list_profiles, load};
use super::sync::{documented, mode_names};

/// One connected Orbbec camera as the SDK and this driver see it.
#[derive(Debug, Clone, PartialEq, Eq)]
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
}

impl CameraInfo {
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
/// [`super::OrbbecOptions::default_library`]). No camera: an empty list. A missing or broken
/// library: `NotFound` naming its path.
pub fn probe(library: &Path) -> Result<Vec<CameraInfo>, OrbbecError> {
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
        drop(pipeline);
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
        });
    }
    if out.len() != usize::try_from(count).unwrap_or(usize::MAX) {
        return Err(OrbbecError::new(ErrorKind::Other, "Orbbec camera list changed while probing"));
    }
    Ok(out)
}
