//! The Orbbec RGB-D camera (Gemini series) through the Orbbec SDK v2 C API, software-triggered.
//!
//! The SDK library is loaded at run time ([`ffi`], the only module with `unsafe`): by default
//! `libOrbbecSDK.so` from `make setup`'s `.deps/lib` (unpacked from the `pyorbbecsdk2` wheel),
//! or the path in the environment variable `HITL_ORBBEC_LIB`. A worker thread ([`worker`]) owns
//! every SDK object; the tick-side [`OrbbecCamera`] only pushes capture requests into a lock-free
//! queue and pops finished frames from another.
//!
//! [`OrbbecCamera::open`] fails before anything moves, with kind `NotFound` and a message naming
//! the Orbbec camera, when the library is missing or no camera is connected.

mod error;
mod ffi;
mod worker;

use std::path::PathBuf;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_channel::{bounded, Sender};
use crossbeam_queue::ArrayQueue;
use hitl_hal::{
    CaptureRequest, ErrorKind, ErrorType, Intrinsics, MonotonicClock, RgbdCamera, RgbdFrame,
    StreamConfig,
};

pub use error::OrbbecError;
use worker::{Command, Shared};

/// Environment variable that overrides the SDK library path.
pub const LIBRARY_ENV: &str = "HITL_ORBBEC_LIB";

/// How to open the camera.
#[derive(Debug, Clone)]
pub struct OrbbecOptions {
    /// Path of `libOrbbecSDK.so`.
    pub library: PathBuf,
    /// Which enumerated camera to use.
    pub device_index: u32,
    /// A software trigger without a frameset within this is a fault.
    pub frame_timeout: Duration,
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
            device_index: 0,
            frame_timeout: Duration::from_millis(1000),
            frame_queue: 4,
            trigger_queue: 8,
            clock: MonotonicClock::new(),
        }
    }
}

/// Which camera was opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OrbbecInfo {
    pub name: String,
    pub serial: String,
    /// SDK version, e.g. "2.9.3".
    pub sdk_version: String,
}

/// An Orbbec camera in software-trigger mode, behind [`RgbdCamera`].
pub struct OrbbecCamera {
    info: OrbbecInfo,
    shared: Arc<Shared>,
    commands: Sender<Command>,
    worker: Option<JoinHandle<()>>,
}

impl OrbbecCamera {
    /// Load the SDK, find the camera and open it. Blocks (about a second) while the SDK starts.
    pub fn open(options: OrbbecOptions) -> Result<Self, OrbbecError> {
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
            .spawn(move || worker::run(options, worker_shared, cmd_rx, ready_tx))
            .map_err(|e| {
                OrbbecError::new(
                    ErrorKind::Other,
                    format!("Orbbec camera: cannot start worker: {e}"),
                )
            })?;
        let info = match ready_rx.recv() {
            Ok(Ok(info)) => info,
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
        Ok(Self { info, shared, commands: cmd_tx, worker: Some(worker) })
    }

    pub fn info(&self) -> &OrbbecInfo {
        &self.info
    }

    /// The full description of the fault that stopped the camera, if any.
    pub fn fault_detail(&self) -> Option<&OrbbecError> {
        self.shared.fault.get()
    }

    /// Frames dropped because `poll_frame` was not called in time.
    pub fn frames_dropped(&self) -> u64 {
        self.shared.frames_dropped()
    }

    fn ask<T>(
        &self,
        make: impl FnOnce(Sender<Result<T, OrbbecError>>) -> Command,
    ) -> Result<T, OrbbecError> {
        self.shared.check()?;
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
        self.ask(Command::Arm)
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
