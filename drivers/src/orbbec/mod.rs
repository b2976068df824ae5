//! The Orbbec RGB-D camera (Gemini 305 family) through the Orbbec SDK v2 C API, hard-synced to
//! the controller's captures.
//!
//! The SDK library is loaded at run time ([`ffi`], the only module with `unsafe`): by default
//! `libOrbbecSDK.so` from `make setup`'s `.deps/lib` (unpacked from the `pyorbbecsdk2` wheel),
//! or the path in the environment variable `HITL_ORBBEC_LIB`. The SDK calls the driver needs sit
//! behind [`CameraSdk`] ([`sdk::SdkCamera`] on the real library; a scripted double in the tests).
//! A worker thread ([`worker`]) owns the camera; the tick-side [`OrbbecCamera`] only pushes
//! capture requests into a lock-free queue and pops finished frames from another.
//!
//! - `configure` picks colour RGB at the asked size and a Y16 depth profile at ONE frame rate
//!   ([`profiles`]); `arm_trigger` sets the trigger mode ([`sync`]: hardware triggering where
//!   Orbbec documents it, software triggering only where documented too), the exposure reference
//!   point (middle), global timestamps, and starts the streams. Depth is aligned to colour by the
//!   SDK's `Align` filter.
//! - Frames are paired with their triggers by timestamps ([`pairing`]); each says whether its
//!   time is the exposure (global timestamp) or the arrival ([`hitl_hal::TimestampSource`]).
//! - Frame metadata from the SDK is checked before use ([`frame`]); a missed frameset is counted,
//!   `max_consecutive_missed` in a row are a fault; a full capture queue is "busy" (`Timeout`).
//! - [`probe`] lists the connected cameras for `hitl probe`.
//! - The camera is left as found: its sync configuration and the settings the driver changes are
//!   saved at open and written back at close (`Lifecycle::stop`, or dropping the handle), and
//!   right away on a fault; a state file ([`marker`]) lets the next open notice and report a run
//!   that could not write them back, and write them back itself.
//! - With several cameras connected, one is picked by serial number ([`OrbbecOptions::serial`]).
//!
//! [`OrbbecCamera::open`] fails before anything moves, with kind `NotFound` and a message naming
//! the Orbbec camera, when the library is missing or no camera is connected. docs/orbbec.md.

mod backend;
mod error;
mod ffi;
pub mod frame;
pub mod marker;
pub mod pairing;
mod probe;
pub mod profiles;
mod sdk;
pub mod sync;
mod worker;

#[cfg(test)]
mod sdk_tests;

use std::path::PathBuf;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_channel::{bounded, Sender};
use crossbeam_queue::ArrayQueue;
use hitl_hal::{
    CaptureRequest, ErrorKind, ErrorType, Intrinsics, Lifecycle, MonotonicClock, RgbdCamera,
    RgbdFrame, StreamConfig,
};

pub use backend::{CameraIdentity, CameraSdk, SavedState, Setting, Stream};
pub use error::OrbbecError;
pub use frame::{FrameMeta, RawFrameset, RawImage};
pub use marker::Leftover;
pub use probe::{probe, probe_with, CameraInfo, Distortion, Lens};
pub use profiles::VideoProfile;
pub use sdk::{pick_camera, SdkCamera};
pub use sync::{SyncConfig, TriggerChoice, TriggerMode};
use worker::{Command, Shared};

/// Which camera was opened (name, serial, product id, firmware, SDK version).
pub type OrbbecInfo = CameraIdentity;

/// Environment variable that overrides the SDK library path.
pub const LIBRARY_ENV: &str = "HITL_ORBBEC_LIB";

/// How to open the camera.
#[derive(Debug, Clone)]
pub struct OrbbecOptions {
    /// Path of `libOrbbecSDK.so`.
    pub library: PathBuf,
    /// The serial number of the camera to use; `None`: the only one connected (several and none
    /// named is refused with `InvalidRequest`, listing them).
    pub serial: Option<String>,
    /// Whether the camera passes each trigger on at its sync output (to a chained camera); off
    /// by default, set explicitly at arm whatever the camera had.
    pub trigger_out: bool,
    /// Where the state file that lets a crashed run be noticed lives ([`marker`]); `None`: no
    /// file is kept (a crash is then not noticed).
    pub state_dir: Option<PathBuf>,
    /// A trigger without a frameset within this is missed (counted).
    pub frame_timeout: Duration,
    /// This many missed framesets in a row are a fault (the camera answers no trigger).
    pub max_consecutive_missed: u32,
    /// How early an exposure stamp may be, against its trigger, and still be that trigger's
    /// frame (the global timestamp's fit error).
    pub pairing_slack: Duration,
    /// Hardware or software triggering (default: hardware where documented).
    pub trigger: TriggerChoice,
    /// `OB_PROP_USB_SYNC_VOLTAGE_LEVEL_INT` to write at arm (None: leave the camera's, 1.8 V by
    /// default on the Gemini 305). Refused by firmware older than 1.0.76.
    pub sync_voltage_level: Option<i32>,
    /// Frames waiting for `poll_frame` (older ones are dropped and counted).
    pub frame_queue: usize,
    /// Capture requests waiting for the worker.
    pub trigger_queue: usize,
    /// The controller's clock, for `exposure_ns`.
    pub clock: MonotonicClock,
}

impl OrbbecOptions {
    /// `$HITL_ORBBEC_LIB`, else `.deps/lib/libOrbbecSDK.so` of this checkout (from `make setup`).
    pub fn default_library() -> PathBuf {
        if let Some(p) = std::env::var_os(LIBRARY_ENV).filter(|p| !p.is_empty()) {
            return PathBuf::from(p);
        }
        match option_env!("HITL_DEPS_LIB") {
            Some(dir) => PathBuf::from(dir).join("libOrbbecSDK.so"),
            None => PathBuf::from("libOrbbecSDK.so"),
        }
    }
}

impl Default for OrbbecOptions {
    fn default() -> Self {
        Self {
            library: Self::default_library(),
            serial: None,
            trigger_out: false,
            state_dir: marker::default_state_dir(),
            frame_timeout: Duration::from_millis(1000),
            max_consecutive_missed: 3,
            pairing_slack: Duration::from_millis(2),
            trigger: TriggerChoice::Auto,
            sync_voltage_level: None,
            frame_queue: 4,
            trigger_queue: 8,
            clock: MonotonicClock::new(),
        }
    }
}

/// What `arm_trigger` set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArmReport {
    pub mode: TriggerMode,
    /// Whether the camera took the exposure reference point "middle of exposure" (cameras
    /// without `OB_PROP_INTRA_CAMERA_SYNC_REFERENCE_INT` keep their own).
    pub exposure_reference_middle: bool,
    /// Whether global (exposure) timestamps are on; else frames carry their arrival time.
    pub global_timestamps: bool,
    pub color: VideoProfile,
    pub depth: VideoProfile,
}

/// What the driver found on the camera at open.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FoundState {
    /// The sync configuration the camera held.
    pub sync: SyncConfig,
    /// The state file of a run that did not write the camera's configuration back: its saved
    /// configuration is the one written back at this camera's close.
    pub leftover: Option<Leftover>,
    /// A state file that could not be read (named, with why).
    pub marker_error: Option<String>,
}

impl FoundState {
    /// What the operator should hear about at open: a configuration a crashed run left, one that
    /// waits for triggers with no record of who set it, or a state file that cannot be read.
    pub fn warning(&self) -> Option<String> {
        if let Some(l) = &self.leftover {
            return Some(format!(
                "{}; the camera holds {}; it gets its configuration back when this session \
                 closes it",
                l.describe(),
                self.sync
            ));
        }
        if let Some(e) = &self.marker_error {
            return Some(format!("Orbbec camera: {e}"));
        }
        self.sync.is_triggered().then(|| {
            format!(
                "the Orbbec camera was found waiting for triggers ({}) with no record of a hitl \
                 run setting it (another tool, or a crash before hitl kept records): other tools \
                 get no frames from it; hitl writes this configuration back when it closes the \
                 camera",
                self.sync
            )
        })
    }
}

/// What opening gave: who the camera is and what it held.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Opened {
    pub identity: CameraIdentity,
    pub found: FoundState,
}

/// An Orbbec camera, hardware- or software-triggered, behind [`RgbdCamera`].
pub struct OrbbecCamera {
    info: OrbbecInfo,
    found: FoundState,
    armed: Option<ArmReport>,
    shared: Arc<Shared>,
    commands: Sender<Command>,
    worker: Option<JoinHandle<()>>,
}

impl OrbbecCamera {
    /// Load the SDK, find the camera and open it. Blocks (about a second) while the SDK starts.
    pub fn open(options: OrbbecOptions) -> Result<Self, OrbbecError> {
        let (library, serial) = (options.library.clone(), options.serial.clone());
        Self::open_with(move || SdkCamera::open(&library, serial.as_deref()), options)
    }

    /// Open through any [`CameraSdk`]: `open` runs on the worker thread, which then owns the
    /// camera (the tests drive the driver through a scripted double this way).
    pub fn open_with<B, F>(open: F, options: OrbbecOptions) -> Result<Self, OrbbecError>
    where
        B: CameraSdk + 'static,
        F: FnOnce() -> Result<B, OrbbecError> + Send + 'static,
    {
        if options.frame_queue == 0 || options.trigger_queue == 0 {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: frame and trigger queues must not be empty",
            ));
        }
        let shared = Arc::new(Shared::new(&options));
        let (cmd_tx, cmd_rx) = bounded(4);
        let (ready_tx, ready_rx) = bounded(1);
        let worker_shared = Arc::clone(&shared);
        let worker = std::thread::Builder::new()
            .name("orbbec".into())
            .spawn(move || worker::run(open, options, worker_shared, cmd_rx, ready_tx))
            .map_err(|e| {
                OrbbecError::new(
                    ErrorKind::Other,
                    format!("Orbbec camera: cannot start worker: {e}"),
                )
            })?;
        let opened = match ready_rx.recv() {
            Ok(Ok(opened)) => opened,
            Ok(Err(e)) => {
                let _ = worker.join();
                return Err(e);
            }
            Err(_) => {
                let _ = worker.join();
                return Err(OrbbecError::new(
                    ErrorKind::Other,
                    "Orbbec camera: worker ended while opening",
                ));
            }
        };
        Ok(Self {
            info: opened.identity,
            found: opened.found,
            armed: None,
            shared,
            commands: cmd_tx,
            worker: Some(worker),
        })
    }

    pub fn info(&self) -> &OrbbecInfo {
        &self.info
    }

    /// What the camera held at open (and a crashed run's leftover, if any): written back at
    /// close.
    pub fn found(&self) -> &FoundState {
        &self.found
    }

    /// The full description of the fault that stopped the camera, if any.
    pub fn fault_detail(&self) -> Option<&OrbbecError> {
        self.shared.fault.get()
    }

    /// The trigger mode `arm_trigger` set (None before).
    pub fn trigger_mode(&self) -> Option<TriggerMode> {
        self.armed.map(|a| a.mode)
    }

    /// What `arm_trigger` set up (None before): mode, exposure reference, timestamps, profiles.
    pub fn armed(&self) -> Option<&ArmReport> {
        self.armed.as_ref()
    }

    /// Frames dropped because `poll_frame` was not called in time.
    pub fn frames_dropped(&self) -> u64 {
        self.shared.frames_dropped()
    }

    /// Triggers that got no frameset within `frame_timeout` (or were given up for newer ones).
    pub fn frames_missed(&self) -> u64 {
        self.shared.frames_missed()
    }

    /// Framesets older than every pending trigger, dropped.
    pub fn frames_stale(&self) -> u64 {
        self.shared.frames_stale()
    }

    /// Framesets refused by the metadata checks (size, format, scale, timestamps).
    pub fn frames_refused(&self) -> u64 {
        self.shared.frames_bad()
    }

    fn ask<T>(
        &self,
        make: impl FnOnce(Sender<Result<T, OrbbecError>>) -> Command,
    ) -> Result<T, OrbbecError> {
        self.shared.check()?;
        self.ask_anyway(make)
    }

    /// Ask the worker even after a fault (closing must still write the configuration back).
    fn ask_anyway<T>(
        &self,
        make: impl FnOnce(Sender<Result<T, OrbbecError>>) -> Command,
    ) -> Result<T, OrbbecError> {
        let (tx, rx) = bounded(1);
        let gone = || OrbbecError::new(ErrorKind::Disconnected, "Orbbec camera: worker has ended");
        self.commands.send(make(tx)).map_err(|_| gone())?;
        rx.recv().map_err(|_| gone())?
    }
}

impl Drop for OrbbecCamera {
    fn drop(&mut self) {
        let _ = self.commands.send(Command::Shutdown);
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

impl ErrorType for OrbbecCamera {
    type Error = OrbbecError;
}

/// `health` is the sticky fault (no allocation); `stop` stops the streams and writes the
/// configuration found at open back (also done when the handle is dropped without it).
impl Lifecycle for OrbbecCamera {
    fn health(&mut self) -> Result<(), OrbbecError> {
        self.shared.check()
    }

    fn stop(&mut self) -> Result<(), OrbbecError> {
        self.ask_anyway(Command::Close)
    }
}

impl RgbdCamera for OrbbecCamera {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, OrbbecError> {
        if config.mask {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: a real camera cannot deliver a target mask",
            ));
        }
        let c = *config;
        self.ask(|reply| Command::Configure(c, reply))
    }

    fn arm_trigger(&mut self) -> Result<(), OrbbecError> {
        let report = self.ask(Command::Arm)?;
        self.armed = Some(report);
        Ok(())
    }

    fn trigger(&mut self, request: CaptureRequest) -> Result<(), OrbbecError> {
        self.shared.check()?;
        self.shared.push_trigger(request)
    }

    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, OrbbecError> {
        if let Some(f) = self.shared.frames.pop() {
            return Ok(Some(f));
        }
        self.shared.check()?;
        Ok(None)
    }
}

/// Now on CLOCK_MONOTONIC in microseconds: the clock of the SDK's system and global timestamps
/// once the driver has set the context to it (for doubles that stamp frames like the SDK).
pub fn sdk_clock_now_us() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(t) => u64::try_from(t.tv_sec())
            .unwrap_or(0)
            .saturating_mul(1_000_000)
            .saturating_add(u64::try_from(t.tv_nsec()).unwrap_or(0) / 1000),
        Err(_) => 0,
    }
}

/// Frames produced by the worker.
pub(crate) type FrameQueue = ArrayQueue<RgbdFrame>;

#[cfg(test)]
mod tests {
    /// The camera handle moves to the real-time thread.
    #[test]
    fn handle_is_send() {
        fn send<T: Send + 'static>() {}
        send::<super::OrbbecCamera>();
    }
}
