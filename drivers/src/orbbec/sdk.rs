//! [`CameraSdk`] on the real Orbbec SDK v2 library (through [`super::ffi`]): opening the first
//! (or n-th) camera, listing its profiles, hard-sync settings, and framesets whose depth the
//! SDK's `Align` filter has put onto the colour image (2.9.3's pipeline D2C mode does nothing).

use std::path::Path;
use std::sync::Arc;

use hitl_hal::{ErrorKind, Intrinsics};

use super::backend::{CameraIdentity, CameraSdk, Setting, Stream};
use super::error::OrbbecError;
use super::ffi::{
    AlignFilter, Context, Device, Frame, Pipeline, Profile, ProfileDesc, Sdk,
    OB_MULTI_DEVICE_SYNC_MODE_HARDWARE_TRIGGERING, OB_MULTI_DEVICE_SYNC_MODE_SOFTWARE_TRIGGERING,
    OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT, OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT, OB_SENSOR_COLOR,
    OB_SENSOR_DEPTH,
};
use super::frame::{check_intrinsics, FrameMeta, RawFrameset, RawImage};
use super::profiles::VideoProfile;
use super::sync::TriggerMode;

/// The loaded SDK and its context (quiet logs, monotonic timestamps).
pub(super) struct Loaded {
    pub sdk: Arc<Sdk>,
    pub context: Context,
    pub version: String,
    pub monotonic: bool,
}

/// Load the library at `path` and make a context; `NotFound` naming the path when it cannot.
pub(super) fn load(path: &Path) -> Result<Loaded, OrbbecError> {
    if !path.exists() {
        return Err(OrbbecError::new(
            ErrorKind::NotFound,
            format!(
                "Orbbec camera: the Orbbec SDK library is missing at {} (run `make setup`, or set \
                 {} to the path of libOrbbecSDK.so)",
                path.display(),
                super::LIBRARY_ENV
            ),
        ));
    }
    let sdk = Sdk::load(path).map_err(|e| {
        OrbbecError::new(
            ErrorKind::NotFound,
            format!("Orbbec camera: cannot load the Orbbec SDK library {}: {e}", path.display()),
        )
    })?;
    let (a, b, c) = sdk.version();
    let version = format!("{a}.{b}.{c}");
    let _ = sdk.quiet_logs();
    let context =
        Context::new(&sdk).map_err(|e| OrbbecError::sdk("creating the SDK context", &e))?;
    let monotonic = context.use_monotonic_timestamps().is_ok();
    Ok(Loaded { sdk, context, version, monotonic })
}

fn desc(p: VideoProfile) -> ProfileDesc {
    ProfileDesc { width: p.width, height: p.height, format: p.format, fps: p.fps }
}

fn profile(d: ProfileDesc) -> VideoProfile {
    VideoProfile { width: d.width, height: d.height, format: d.format, fps: d.fps }
}

pub(super) fn identity_of(device: &Device, version: &str) -> Result<CameraIdentity, OrbbecError> {
    let id = device.describe().map_err(|e| OrbbecError::sdk("reading device info", &e))?;
    Ok(CameraIdentity {
        name: id.name,
        serial: id.serial,
        product_id: u16::try_from(id.pid).unwrap_or(0),
        firmware: id.firmware,
        sdk_version: version.to_string(),
    })
}

pub(super) fn list_profiles(
    pipeline: &Pipeline,
    stream: Stream,
) -> Result<Vec<VideoProfile>, OrbbecError> {
    let sensor = match stream {
        Stream::Color => OB_SENSOR_COLOR,
        Stream::Depth => OB_SENSOR_DEPTH,
    };
    Ok(pipeline
        .profiles(sensor)
        .map_err(|e| OrbbecError::sdk("listing stream profiles", &e))?
        .into_iter()
        .map(profile)
        .collect())
}

/// One opened Orbbec camera. Field order is drop order: filter, pipeline, profiles, device, then
/// the context.
pub struct SdkCamera {
    align: Option<AlignFilter>,
    pipeline: Pipeline,
    device: Device,
    _context: Context,
    sdk: Arc<Sdk>,
    version: String,
    monotonic: bool,
}

impl SdkCamera {
    /// Open camera number `index` of the library at `path`.
    pub fn open(path: &Path, index: u32) -> Result<SdkCamera, OrbbecError> {
        let Loaded { sdk, context, version, monotonic } = load(path)?;
        let list = context.devices().map_err(|e| OrbbecError::sdk("listing devices", &e))?;
        let count = list.count().map_err(|e| OrbbecError::sdk("counting devices", &e))?;
        if count == 0 {
            return Err(OrbbecError::new(
                ErrorKind::NotFound,
                format!(
                    "no Orbbec camera found: Orbbec SDK {version} ({}) sees no device; connect \
                     the Orbbec camera (USB 3) and install its udev rules",
                    path.display()
                ),
            ));
        }
        if index >= count {
            return Err(OrbbecError::new(
                ErrorKind::NotFound,
                format!("Orbbec camera #{index} not found: the Orbbec SDK sees {count} camera(s)"),
            ));
        }
        let device =
            list.device(index).map_err(|e| OrbbecError::sdk("opening the Orbbec camera", &e))?;
        drop(list);
        let pipeline =
            Pipeline::new(&device).map_err(|e| OrbbecError::sdk("creating the pipeline", &e))?;
        Ok(SdkCamera { align: None, pipeline, device, _context: context, sdk, version, monotonic })
    }

    fn find(&self, sensor: i32, p: VideoProfile) -> Result<Profile, OrbbecError> {
        self.pipeline.video_profile(sensor, desc(p)).map_err(|e| {
            OrbbecError::new(
                ErrorKind::InvalidRequest,
                format!("Orbbec camera has no stream profile {p}: {e}"),
            )
        })
    }
}

/// Copy one SDK video frame (metadata and bytes) out of the library.
fn copy_image(frame: &Frame, depth: bool) -> Result<RawImage, OrbbecError> {
    let what = if depth { "depth frame" } else { "colour frame" };
    let err = |e| OrbbecError::sdk(what, &e);
    let (width, height) = frame.size().map_err(err)?;
    let (device_us, system_us, global_us) = frame.timestamps_us().map_err(err)?;
    let depth_scale_mm = if depth { frame.depth_scale_mm().map_err(err)? } else { 0.0 };
    let meta = FrameMeta {
        width,
        height,
        format: frame.format().map_err(err)?,
        device_us,
        system_us,
        global_us,
        depth_scale_mm,
    };
    Ok(RawImage { meta, data: frame.data().map_err(err)?.to_vec() })
}

/// Run `frameset` through the `Align` filter (depth onto colour) and copy colour and the aligned
/// depth out. A frameset the filter refuses keeps its depth out (`depth: None`).
pub(super) fn align_and_copy(
    align: &mut AlignFilter,
    frameset: &Frame,
) -> Result<RawFrameset, OrbbecError> {
    let aligned = align.process(frameset).map_err(|e| OrbbecError::sdk("aligning depth", &e))?;
    let Some(aligned) = aligned else {
        return Ok(RawFrameset { color: None, depth: None });
    };
    let color = aligned.color().map_err(|e| OrbbecError::sdk("colour frame", &e))?;
    let depth = aligned.depth().map_err(|e| OrbbecError::sdk("depth frame", &e))?;
    Ok(RawFrameset {
        color: color.as_ref().map(|f| copy_image(f, false)).transpose()?,
        depth: depth.as_ref().map(|f| copy_image(f, true)).transpose()?,
    })
}

impl CameraSdk for SdkCamera {
    fn identity(&mut self) -> Result<CameraIdentity, OrbbecError> {
        identity_of(&self.device, &self.version)
    }

    fn profiles(&mut self, stream: Stream) -> Result<Vec<VideoProfile>, OrbbecError> {
        list_profiles(&self.pipeline, stream)
    }

    fn intrinsics(&mut self, color: VideoProfile) -> Result<Intrinsics, OrbbecError> {
        let p = self.find(OB_SENSOR_COLOR, color)?;
        let k = p.intrinsic().map_err(|e| OrbbecError::sdk("reading colour intrinsics", &e))?;
        check_intrinsics(k.fx, k.fy, k.cx, k.cy, color.width, color.height)
    }

    fn advertised_sync_modes(&mut self) -> Result<u16, OrbbecError> {
        self.device.sync_modes().map_err(|e| OrbbecError::sdk("reading sync modes", &e))
    }

    fn set_trigger_mode(&mut self, mode: TriggerMode) -> Result<(), OrbbecError> {
        let mut sync =
            self.device.sync_config().map_err(|e| OrbbecError::sdk("reading sync config", &e))?;
        sync.sync_mode = match mode {
            TriggerMode::Hardware => OB_MULTI_DEVICE_SYNC_MODE_HARDWARE_TRIGGERING,
            TriggerMode::Software => OB_MULTI_DEVICE_SYNC_MODE_SOFTWARE_TRIGGERING,
        };
        sync.frames_per_trigger = 1;
        sync.trigger_to_image_delay_us = 0;
        sync.depth_delay_us = 0;
        sync.color_delay_us = 0;
        self.device
            .set_sync_config(&sync)
            .map_err(|e| OrbbecError::sdk(&format!("setting {mode}"), &e))
    }

    fn set(&mut self, setting: Setting, value: i32) -> Result<bool, OrbbecError> {
        let id = match setting {
            Setting::ExposureReference => OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT,
            Setting::SyncVoltageLevel => OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT,
        };
        let doing = format!("setting {setting:?} to {value}");
        if !self.device.property_writable(id).map_err(|e| OrbbecError::sdk(&doing, &e))? {
            return Ok(false);
        }
        self.device.set_int_property(id, value).map_err(|e| OrbbecError::sdk(&doing, &e))?;
        Ok(true)
    }

    fn enable_global_timestamps(&mut self) -> Result<bool, OrbbecError> {
        self.device
            .enable_global_timestamps()
            .map_err(|e| OrbbecError::sdk("enabling global timestamps", &e))
    }

    fn monotonic_stamps(&self) -> bool {
        self.monotonic
    }

    fn start(&mut self, color: VideoProfile, depth: VideoProfile) -> Result<(), OrbbecError> {
        let c = self.find(OB_SENSOR_COLOR, color)?;
        let d = self.find(OB_SENSOR_DEPTH, depth)?;
        let align = AlignFilter::depth_to_color(&self.sdk)
            .map_err(|e| OrbbecError::sdk("creating the Align filter", &e))?;
        self.pipeline
            .start(&c, &d)
            .map_err(|e| OrbbecError::sdk("starting colour + depth streams", &e))?;
        self.align = Some(align);
        Ok(())
    }

    fn software_trigger(&mut self) -> Result<(), OrbbecError> {
        self.device.trigger_capture().map_err(|e| OrbbecError::sdk("software trigger", &e))
    }

    fn wait_frameset(&mut self, timeout_ms: u32) -> Result<Option<RawFrameset>, OrbbecError> {
        let Some(align) = self.align.as_mut() else {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: waiting for frames before the streams started",
            ));
        };
        let set = self
            .pipeline
            .wait_frameset(timeout_ms)
            .map_err(|e| OrbbecError::sdk("waiting for a frameset", &e))?;
        set.map(|s| align_and_copy(align, &s)).transpose()
    }
}
