//! [`CameraSdk`] on the real Orbbec SDK v2 library (through [`super::ffi`]): opening the camera
//! with a given serial number (or the only one connected), listing its profiles, hard-sync
//! settings, and framesets whose depth the SDK's `Align` filter has put onto the colour image
//! (2.9.3's pipeline D2C mode does nothing).

use std::path::Path;
use std::sync::Arc;

use hitl_hal::{ErrorKind, Intrinsics};

use super::backend::{CameraIdentity, CameraSdk, Setting, Stream};
use super::error::OrbbecError;
use super::ffi::ObMultiDeviceSyncConfig;
use super::ffi::{
    AlignFilter, Context, Device, Frame, Pipeline, Profile, ProfileDesc, Sdk,
    OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT, OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT, OB_SENSOR_COLOR,
    OB_SENSOR_DEPTH,
};
use super::frame::{check_distortion, check_intrinsics, FrameMeta, RawFrameset, RawImage};
use super::profiles::VideoProfile;
use super::sync::SyncConfig;

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

pub(super) fn property_id(setting: Setting) -> i32 {
    match setting {
        Setting::ExposureReference => OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT,
        Setting::SyncVoltageLevel => OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT,
    }
}

pub(super) fn sync_from_ffi(c: &ObMultiDeviceSyncConfig) -> Result<SyncConfig, OrbbecError> {
    // Copies out of the packed struct (no references into it).
    let (mode, depth, color, t2i) =
        (c.sync_mode, c.depth_delay_us, c.color_delay_us, c.trigger_to_image_delay_us);
    let (out, out_delay, frames) =
        (c.trigger_out_enable, c.trigger_out_delay_us, c.frames_per_trigger);
    let mode = u16::try_from(mode).ok().filter(|m| m.count_ones() <= 1).ok_or_else(|| {
        OrbbecError::new(ErrorKind::DeviceFault, format!("Orbbec camera reports sync mode {mode}"))
    })?;
    Ok(SyncConfig {
        mode,
        depth_delay_us: depth,
        color_delay_us: color,
        trigger_to_image_delay_us: t2i,
        trigger_out_enable: out,
        trigger_out_delay_us: out_delay,
        frames_per_trigger: frames,
    })
}

fn sync_to_ffi(c: &SyncConfig) -> ObMultiDeviceSyncConfig {
    ObMultiDeviceSyncConfig {
        sync_mode: i32::from(c.mode),
        depth_delay_us: c.depth_delay_us,
        color_delay_us: c.color_delay_us,
        trigger_to_image_delay_us: c.trigger_to_image_delay_us,
        trigger_out_enable: c.trigger_out_enable,
        trigger_out_delay_us: c.trigger_out_delay_us,
        frames_per_trigger: c.frames_per_trigger,
    }
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

/// Which of the connected cameras (`serials`, in the SDK's order) to open: the one with serial
/// number `wanted` (compared without case, as Orbbec's multi-device example does), else the only
/// one. No camera, or no camera with that serial: `NotFound`; several and none named:
/// `InvalidRequest` listing them (the operator must say which).
pub fn pick_camera(serials: &[String], wanted: Option<&str>) -> Result<u32, OrbbecError> {
    let list = || serials.join(", ");
    let index = |i: usize| u32::try_from(i).unwrap_or(u32::MAX);
    match (wanted, serials.len()) {
        (_, 0) => Err(OrbbecError::new(ErrorKind::NotFound, "no Orbbec camera found")),
        (Some(w), _) => {
            serials.iter().position(|s| s.eq_ignore_ascii_case(w)).map(index).ok_or_else(|| {
                OrbbecError::new(
                    ErrorKind::NotFound,
                    format!("no Orbbec camera with serial {w}: connected: {}", list()),
                )
            })
        }
        (None, 1) => Ok(0),
        (None, n) => Err(OrbbecError::new(
            ErrorKind::InvalidRequest,
            format!(
                "{n} Orbbec cameras are connected (serials {}): name one with --camera \
                 orbbec@SERIAL",
                list()
            ),
        )),
    }
}

impl SdkCamera {
    /// Open the camera with serial number `serial` (or the only one connected) through the
    /// library at `path`.
    pub fn open(path: &Path, serial: Option<&str>) -> Result<SdkCamera, OrbbecError> {
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
        let serials = (0..count.min(64))
            .map(|i| list.serial(i).map_err(|e| OrbbecError::sdk("reading serial numbers", &e)))
            .collect::<Result<Vec<_>, _>>()?;
        let index = pick_camera(&serials, serial)?;
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
        // The colour lens's factory calibration: the aligned depth is registered into the
        // distorted colour image (`AlignFilter`), so both carry it.
        let d = p.distortion().map_err(|e| OrbbecError::sdk("reading colour distortion", &e))?;
        let lens = check_distortion(d.k, d.p1, d.p2, d.model)?;
        Ok(check_intrinsics(k.fx, k.fy, k.cx, k.cy, color.width, color.height)?
            .with_distortion(lens))
    }

    fn advertised_sync_modes(&mut self) -> Result<u16, OrbbecError> {
        self.device.sync_modes().map_err(|e| OrbbecError::sdk("reading sync modes", &e))
    }

    fn sync_config(&mut self) -> Result<SyncConfig, OrbbecError> {
        let c =
            self.device.sync_config().map_err(|e| OrbbecError::sdk("reading sync config", &e))?;
        sync_from_ffi(&c)
    }

    fn set_sync_config(&mut self, config: &SyncConfig) -> Result<(), OrbbecError> {
        self.device
            .set_sync_config(&sync_to_ffi(config))
            .map_err(|e| OrbbecError::sdk(&format!("setting sync config ({config})"), &e))
    }

    fn get(&mut self, setting: Setting) -> Result<Option<i32>, OrbbecError> {
        let id = property_id(setting);
        let doing = format!("reading {setting:?}");
        if !self.device.property_readable(id).map_err(|e| OrbbecError::sdk(&doing, &e))? {
            return Ok(None);
        }
        self.device.int_property(id).map(Some).map_err(|e| OrbbecError::sdk(&doing, &e))
    }

    fn set(&mut self, setting: Setting, value: i32) -> Result<bool, OrbbecError> {
        let id = property_id(setting);
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
        // Into the distorted colour image where the colour lens has a distortion.
        let lens = c.distortion().map_err(|e| OrbbecError::sdk("reading colour distortion", &e))?;
        let distorted = !check_distortion(lens.k, lens.p1, lens.p2, lens.model)?.is_none();
        let align = AlignFilter::depth_to_color(&self.sdk, distorted)
            .map_err(|e| OrbbecError::sdk("creating the Align filter", &e))?;
        self.pipeline
            .start(&c, &d)
            .map_err(|e| OrbbecError::sdk("starting colour + depth streams", &e))?;
        self.align = Some(align);
        Ok(())
    }

    fn stop(&mut self) -> Result<(), OrbbecError> {
        self.align = None;
        self.pipeline.stop().map_err(|e| OrbbecError::sdk("stopping the streams", &e))
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

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_hal::Error as _;

    fn serials(s: &[&str]) -> Vec<String> {
        s.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_camera_is_picked_by_serial_or_as_the_only_one() {
        assert_eq!(pick_camera(&serials(&["CP1"]), None), Ok(0));
        assert_eq!(pick_camera(&serials(&["CP1", "CP2"]), Some("cp2")), Ok(1));
        let e = pick_camera(&serials(&["CP1", "CP2"]), None).expect_err("which one?");
        assert_eq!(e.kind(), ErrorKind::InvalidRequest);
        assert!(e.message().contains("serials CP1, CP2") && e.message().contains("@SERIAL"), "{e}");
        let e = pick_camera(&serials(&["CP1"]), Some("CP9")).expect_err("not connected");
        assert_eq!(e.kind(), ErrorKind::NotFound);
        assert!(e.message().contains("CP9") && e.message().contains("connected: CP1"), "{e}");
        assert_eq!(pick_camera(&[], None).map_err(|e| e.kind()), Err(ErrorKind::NotFound));
    }
}
