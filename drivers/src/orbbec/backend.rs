//! The SDK surface the Orbbec worker needs, as a small trait: the real library
//! ([`super::sdk::SdkCamera`]) implements it, and so can a scripted double in the tests, which
//! then drives the worker's whole state machine (configure -> arm -> trigger -> frames, missed,
//! stale and late framesets, a full queue, an unplugged camera) without a camera.

use hitl_hal::Intrinsics;

use super::error::OrbbecError;
use super::frame::RawFrameset;
use super::profiles::VideoProfile;
use super::sync::SyncConfig;

/// What a camera says about itself.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraIdentity {
    pub name: String,
    pub serial: String,
    /// USB product id (Gemini 305: 0x0840/0x0841, Gemini 305g: 0x0842).
    pub product_id: u16,
    pub firmware: String,
    /// Version of the SDK that answered, e.g. "2.9.3".
    pub sdk_version: String,
}

/// Which of the camera's streams.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    Color,
    Depth,
}

/// Device settings the driver writes (integer properties of the SDK).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// `OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT`: which point of the exposure (0 start, 1 middle,
    /// 2 end) colour and depth are synchronised on.
    ExposureReference,
    /// `OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT`: the I/O level of the USB-C sync pins (firmware >=
    /// 1.0.76 on the Gemini 305; 1.8 V by default).
    SyncVoltageLevel,
}

impl Setting {
    /// Every setting the driver may write (and so saves at open and writes back at close).
    pub const ALL: [Setting; 2] = [Setting::ExposureReference, Setting::SyncVoltageLevel];

    /// The name in the state file and in messages.
    pub fn key(self) -> &'static str {
        match self {
            Setting::ExposureReference => "exposure_reference",
            Setting::SyncVoltageLevel => "sync_voltage_level",
        }
    }
}

/// What the driver found on the camera and writes back when it lets the camera go: the sync
/// configuration, and each setting it may change that the camera lets it read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedState {
    pub sync: SyncConfig,
    pub settings: Vec<(Setting, i32)>,
}

/// The SDK calls the worker makes, in the order it makes them: identity, sync configuration and
/// settings (saved) at open, profiles at configure; sync configuration, settings, global
/// timestamps and start at arm; then triggers and framesets; at close (or on a fault) stop and
/// the saved sync configuration and settings written back. Every call happens on the worker
/// thread.
pub trait CameraSdk {
    fn identity(&mut self) -> Result<CameraIdentity, OrbbecError>;
    fn profiles(&mut self, stream: Stream) -> Result<Vec<VideoProfile>, OrbbecError>;
    /// The colour intrinsics of `color` (checked).
    fn intrinsics(&mut self, color: VideoProfile) -> Result<Intrinsics, OrbbecError>;
    /// `OB_MULTI_DEVICE_SYNC_MODE_*` bits the SDK advertises.
    fn advertised_sync_modes(&mut self) -> Result<u16, OrbbecError>;
    /// The sync configuration the camera holds now.
    fn sync_config(&mut self) -> Result<SyncConfig, OrbbecError>;
    /// Write the whole sync configuration.
    fn set_sync_config(&mut self, config: &SyncConfig) -> Result<(), OrbbecError>;
    /// Read `setting`; `Ok(None)` when the camera does not let it be read.
    fn get(&mut self, setting: Setting) -> Result<Option<i32>, OrbbecError>;
    /// Write `setting`; `Ok(false)` when the camera does not offer it.
    fn set(&mut self, setting: Setting, value: i32) -> Result<bool, OrbbecError>;
    /// Turn on global (exposure) timestamps where supported; returns whether they are on.
    fn enable_global_timestamps(&mut self) -> Result<bool, OrbbecError>;
    /// Whether frame system timestamps are on CLOCK_MONOTONIC (else CLOCK_REALTIME).
    fn monotonic_stamps(&self) -> bool;
    /// Start both streams (colour, and depth to be aligned to it).
    fn start(&mut self, color: VideoProfile, depth: VideoProfile) -> Result<(), OrbbecError>;
    /// One software trigger (`ob_device_trigger_capture`).
    fn software_trigger(&mut self) -> Result<(), OrbbecError>;
    /// The next frameset, depth aligned to colour, or `None` after `timeout_ms`.
    fn wait_frameset(&mut self, timeout_ms: u32) -> Result<Option<RawFrameset>, OrbbecError>;
    /// Stop the streams (nothing when they are not running), before the saved configuration is
    /// written back.
    fn stop(&mut self) -> Result<(), OrbbecError>;
}
