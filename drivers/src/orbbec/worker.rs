//! The Orbbec worker thread: owns the camera (any [`CameraSdk`]), and runs its state machine:
//! opened -> configured (profiles chosen) -> streaming (trigger mode set, streams started) ->
//! faulted (sticky). While streaming it fires software triggers for capture requests (software
//! mode only; in hardware mode the trigger box fires the camera's sync input), waits for
//! framesets, checks them, pairs each with its trigger by timestamps ([`Pairing`]) and hands the
//! frames to the tick-side handle through a lock-free queue.
//!
//! A missed frameset is counted, not a fault; `max_consecutive_missed` misses in a row (the
//! camera answers no trigger any more) are. Framesets older than their trigger are stale: dropped
//! and counted.
//!
//! The camera is left as found: at open the worker reads the sync configuration and the settings
//! it may change ([`SavedState`]), and a state file a crashed run left ([`super::marker`]); before
//! it changes anything at arm it writes the state file; at close, on a fault and at shutdown it
//! stops the streams, writes the saved state back and removes the file.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TryRecvError};
use crossbeam_queue::ArrayQueue;
use hitl_hal::{
    CaptureRequest, Clock, ErrorKind, Intrinsics, MonotonicClock, RgbdFrame, StreamConfig,
    TimestampSource,
};
use nix::time::{clock_gettime, ClockId};

use super::backend::{CameraSdk, SavedState, Setting, Stream};
use super::error::OrbbecError;
use super::ffi::OB_MIDDLE_OF_EXPOSURE;
use super::frame::{check_frameset, RawFrameset};
use super::marker;
use super::pairing::{Paired, Pairing};
use super::profiles::{choose_profiles, VideoProfile};
use super::sync::{choose_trigger, SyncConfig, TriggerMode};
use super::{ArmReport, FoundState, FrameQueue, Opened, OrbbecOptions};

/// How long one wait for a frameset lasts, so commands are still answered promptly.
const POLL_MS: u32 = 5;

/// Requests from the handle that need an answer (never sent from the tick).
pub(super) enum Command {
    Configure(StreamConfig, Sender<Result<Intrinsics, OrbbecError>>),
    Arm(Sender<Result<ArmReport, OrbbecError>>),
    /// Stop the streams and write the saved state back (the handle's `Lifecycle::stop`).
    Close(Sender<Result<(), OrbbecError>>),
    Shutdown,
}

/// State shared by the tick-side handle and the worker: lock-free queues, counters and a sticky
/// fault.
pub(super) struct Shared {
    pub frames: FrameQueue,
    triggers: ArrayQueue<CaptureRequest>,
    armed: AtomicBool,
    /// 0 = healthy, else `1 + ErrorKind index` of the fault (readable without locks).
    fault_kind: AtomicU8,
    pub fault: OnceLock<OrbbecError>,
    dropped: AtomicU64,
    missed: AtomicU64,
    stale: AtomicU64,
    bad: AtomicU64,
}

const KINDS: [ErrorKind; 7] = [
    ErrorKind::Disconnected,
    ErrorKind::Timeout,
    ErrorKind::Protocol,
    ErrorKind::DeviceFault,
    ErrorKind::NotFound,
    ErrorKind::InvalidRequest,
    ErrorKind::Other,
];

impl Shared {
    pub fn new(options: &OrbbecOptions) -> Self {
        Self {
            frames: ArrayQueue::new(options.frame_queue),
            triggers: ArrayQueue::new(options.trigger_queue),
            armed: AtomicBool::new(false),
            fault_kind: AtomicU8::new(0),
            fault: OnceLock::new(),
            dropped: AtomicU64::new(0),
            missed: AtomicU64::new(0),
            stale: AtomicU64::new(0),
            bad: AtomicU64::new(0),
        }
    }

    fn trip(&self, e: OrbbecError) {
        let idx = KINDS.iter().position(|k| *k == hitl_hal::Error::kind(&e)).unwrap_or(6);
        let _ = self.fault.set(e);
        let _ = self.fault_kind.compare_exchange(
            0,
            u8::try_from(idx + 1).unwrap_or(7),
            Ordering::AcqRel,
            Ordering::Acquire,
        );
    }

    fn faulted(&self) -> bool {
        self.fault_kind.load(Ordering::Acquire) != 0
    }

    /// `Ok` while healthy. Never allocates (the detail is in `fault`).
    pub fn check(&self) -> Result<(), OrbbecError> {
        match self.fault_kind.load(Ordering::Acquire) {
            0 => Ok(()),
            k => Err(OrbbecError::new(
                KINDS.get(usize::from(k) - 1).copied().unwrap_or(ErrorKind::Other),
                "Orbbec camera stopped on a fault (see OrbbecCamera::fault_detail)",
            )),
        }
    }

    /// From the tick: queue a capture request. A full queue is "busy" (`Timeout`): this capture
    /// is lost, the camera still works. Never allocates or blocks.
    pub fn push_trigger(&self, request: CaptureRequest) -> Result<(), OrbbecError> {
        if !self.armed.load(Ordering::Acquire) {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: trigger before arm_trigger",
            ));
        }
        self.triggers.push(request).map_err(|_| {
            OrbbecError::new(ErrorKind::Timeout, "Orbbec camera: capture queue is full (busy)")
        })
    }

    pub fn frames_dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    pub fn frames_missed(&self) -> u64 {
        self.missed.load(Ordering::Relaxed)
    }

    pub fn frames_stale(&self) -> u64 {
        self.stale.load(Ordering::Relaxed)
    }

    pub fn frames_bad(&self) -> u64 {
        self.bad.load(Ordering::Relaxed)
    }
}

/// Where the worker's camera is in its life.
enum State {
    Opened,
    Configured { color: VideoProfile, depth: VideoProfile, k: Intrinsics },
    Streaming(Streaming),
}

#[derive(Clone, Copy)]
struct Streaming {
    mode: TriggerMode,
    k: Intrinsics,
    global: bool,
    monotonic: bool,
    report: ArmReport,
}

struct Worker<B> {
    cam: B,
    /// What to write back when the camera is let go, and the state file that records it.
    saved: SavedState,
    marker: Option<std::path::PathBuf>,
    serial: String,
    /// The camera holds a configuration that is not `saved` (set at arm, or left by a crash).
    restore_pending: bool,
    /// A restore was tried after a fault (not repeated every round).
    restore_tried_on_fault: bool,
    options: OrbbecOptions,
    shared: std::sync::Arc<Shared>,
    state: State,
    pairing: Pairing,
    consecutive_missed: u32,
    last_bad: Option<OrbbecError>,
}

impl<B: CameraSdk> Worker<B> {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, OrbbecError> {
        if matches!(self.state, State::Streaming(_)) {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: configure after arm_trigger (the streams are running)",
            ));
        }
        let (w, h) = (config.intrinsics.width, config.intrinsics.height);
        let colors = self.cam.profiles(Stream::Color)?;
        let depths = self.cam.profiles(Stream::Depth)?;
        let (color, depth) = choose_profiles(&colors, &depths, w, h)?;
        let k = self.cam.intrinsics(color)?;
        if (k.width, k.height) != (w, h) {
            return Err(OrbbecError::new(
                ErrorKind::DeviceFault,
                format!(
                    "Orbbec camera: colour profile {color} reports a {}x{} image",
                    k.width, k.height
                ),
            ));
        }
        self.state = State::Configured { color, depth, k };
        Ok(k)
    }

    fn arm(&mut self) -> Result<ArmReport, OrbbecError> {
        let (color, depth, k) = match &self.state {
            State::Opened => {
                return Err(OrbbecError::new(
                    ErrorKind::InvalidRequest,
                    "Orbbec camera: arm_trigger before configure",
                ))
            }
            State::Streaming(s) => return Ok(s.report),
            State::Configured { color, depth, k } => (*color, *depth, *k),
        };
        let id = self.cam.identity()?;
        let advertised = self.cam.advertised_sync_modes()?;
        let mode = choose_trigger(id.product_id, advertised, self.options.trigger)?;
        // The state file first: a crash from here on is noticed at the next open.
        if let Some(path) = &self.marker {
            marker::write(path, &self.serial, &self.saved).map_err(|e| {
                OrbbecError::new(
                    ErrorKind::InvalidRequest,
                    format!(
                        "Orbbec camera: cannot write the state file {} that lets a crashed run be \
                         noticed ({e}); set {} to a writable folder",
                        path.display(),
                        marker::STATE_DIR_ENV
                    ),
                )
            })?;
        }
        self.restore_pending = true;
        self.cam.set_sync_config(&SyncConfig::for_run(mode, self.options.trigger_out))?;
        // Optional on older firmware (reported); the lab check says which point the stamps mark.
        let exposure_reference_middle =
            self.cam.set(Setting::ExposureReference, OB_MIDDLE_OF_EXPOSURE)?;
        if let Some(level) = self.options.sync_voltage_level {
            if !self.cam.set(Setting::SyncVoltageLevel, level)? {
                return Err(OrbbecError::new(
                    ErrorKind::InvalidRequest,
                    format!(
                        "Orbbec {} (firmware {}) cannot set the sync voltage level (needs \
                         firmware >= 1.0.76)",
                        id.name, id.firmware
                    ),
                ));
            }
        }
        let global = self.cam.enable_global_timestamps()?;
        self.cam.start(color, depth)?;
        let monotonic = self.cam.monotonic_stamps();
        let report =
            ArmReport { mode, exposure_reference_middle, global_timestamps: global, color, depth };
        self.state = State::Streaming(Streaming { mode, k, global, monotonic, report });
        Ok(report)
    }

    /// Stop the streams and write the saved state back; the state file goes once that worked.
    /// Nothing to do when the camera holds what was found.
    fn restore(&mut self) -> Result<(), OrbbecError> {
        if !self.restore_pending {
            return Ok(());
        }
        self.shared.armed.store(false, Ordering::Release);
        let stopped = self.cam.stop();
        self.state = State::Opened;
        self.cam.set_sync_config(&self.saved.sync)?;
        for (setting, value) in self.saved.settings.clone() {
            self.cam.set(setting, value)?;
        }
        self.restore_pending = false;
        if let Some(path) = &self.marker {
            marker::remove(path).map_err(|e| {
                OrbbecError::new(
                    ErrorKind::Other,
                    format!(
                        "Orbbec camera: its configuration was written back, but the state file \
                         {} could not be removed: {e}",
                        path.display()
                    ),
                )
            })?;
        }
        stopped
    }

    fn missed(&mut self, n: u32, mode: TriggerMode) {
        if n == 0 {
            return;
        }
        self.shared.missed.fetch_add(u64::from(n), Ordering::Relaxed);
        self.consecutive_missed = self.consecutive_missed.saturating_add(n);
        if self.consecutive_missed >= self.options.max_consecutive_missed {
            let hint = match mode {
                TriggerMode::Hardware => {
                    "; is the trigger box's camera line wired to the camera's sync input?"
                }
                TriggerMode::Software => "",
            };
            let last = match &self.last_bad {
                Some(e) => format!("; last refused frameset: {}", e.message()),
                None => String::new(),
            };
            self.shared.trip(OrbbecError::new(
                ErrorKind::DeviceFault,
                format!(
                    "Orbbec camera answered none of the last {} triggers ({mode}){hint}{last}",
                    self.consecutive_missed
                ),
            ));
        }
    }

    fn frameset(&mut self, set: &RawFrameset, s: &Streaming) {
        let (color, depth_m, stamp_us, exposure, device_ns) =
            match check_frameset(set, &s.k, s.global) {
                Ok(v) => v,
                Err(e) => {
                    self.shared.bad.fetch_add(1, Ordering::Relaxed);
                    self.last_bad = Some(e);
                    return;
                }
            };
        let exposure_ns = host_ns(stamp_us, s.monotonic, &self.options.clock);
        // A hardware trigger's frame can come in before the tick's request was taken over.
        if !self.take_triggers(s.mode) {
            return;
        }
        match self.pairing.pair(exposure_ns, exposure) {
            Paired::Stale => {
                self.shared.stale.fetch_add(1, Ordering::Relaxed);
            }
            Paired::Frame { request, missed } => {
                self.shared.missed.fetch_add(u64::from(missed), Ordering::Relaxed);
                self.consecutive_missed = 0;
                let frame = RgbdFrame {
                    request,
                    device_ns,
                    exposure_ns,
                    timestamp: if exposure {
                        TimestampSource::DeviceExposure
                    } else {
                        TimestampSource::HostArrival
                    },
                    intrinsics: s.k,
                    color: Arc::new(color),
                    depth_m: Arc::new(depth_m),
                    mask: None,
                };
                if self.shared.frames.force_push(frame).is_some() {
                    self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// Move the tick's capture requests into the pairing (firing a software trigger for each in
    /// software mode). False when the camera tripped.
    fn take_triggers(&mut self, mode: TriggerMode) -> bool {
        while let Some(req) = self.shared.triggers.pop() {
            if mode == TriggerMode::Software {
                if let Err(e) = self.cam.software_trigger() {
                    self.shared.trip(e);
                    return false;
                }
            }
            if self.pairing.push(req).is_some() {
                self.missed(1, mode);
            }
        }
        !self.shared.faulted()
    }

    /// One round while streaming: fire queued triggers, wait briefly for a frameset, expire.
    fn stream_once(&mut self) {
        let State::Streaming(s) = &self.state else { return };
        let s = *s;
        if !self.take_triggers(s.mode) {
            return;
        }
        match self.cam.wait_frameset(POLL_MS) {
            Err(e) => {
                self.shared.trip(e);
                return;
            }
            Ok(Some(set)) => self.frameset(&set, &s),
            Ok(None) => {}
        }
        let timeout_ns = u64::try_from(self.options.frame_timeout.as_nanos()).unwrap_or(u64::MAX);
        let n = self.pairing.expire(self.options.clock.now_ns(), timeout_ns);
        self.missed(n, s.mode);
    }
}

/// Map an SDK host timestamp (CLOCK_MONOTONIC or CLOCK_REALTIME, µs) onto `clock`.
pub(super) fn host_ns(system_us: u64, monotonic: bool, clock: &MonotonicClock) -> u64 {
    let id = if monotonic { ClockId::CLOCK_MONOTONIC } else { ClockId::CLOCK_REALTIME };
    let Ok(now) = clock_gettime(id) else {
        return clock.now_ns();
    };
    let now_ns = u64::try_from(now.tv_sec())
        .unwrap_or(0)
        .saturating_mul(1_000_000_000)
        .saturating_add(u64::try_from(now.tv_nsec()).unwrap_or(0));
    let age_ns = now_ns.saturating_sub(system_us.saturating_mul(1000));
    clock.now_ns().saturating_sub(age_ns)
}

/// Read what the camera holds (sync configuration, the settings the driver may change) and the
/// state file of a run that did not write its camera back: what to write back at close.
fn save_state<B: CameraSdk>(
    cam: &mut B,
    serial: &str,
    options: &OrbbecOptions,
) -> Result<(SavedState, FoundState, Option<std::path::PathBuf>), OrbbecError> {
    let sync = cam.sync_config()?;
    let mut settings = Vec::new();
    for setting in Setting::ALL {
        if let Some(v) = cam.get(setting)? {
            settings.push((setting, v));
        }
    }
    let path = options.state_dir.as_deref().map(|d| marker::marker_path(d, serial));
    let (leftover, marker_error) = match path.as_deref().map(marker::read) {
        None | Some(Ok(None)) => (None, None),
        Some(Ok(Some(l))) => (Some(l), None),
        Some(Err(e)) => (None, Some(e)),
    };
    let saved = match &leftover {
        Some(l) => l.saved.clone(),
        None => SavedState { sync, settings },
    };
    Ok((saved, FoundState { sync, leftover, marker_error }, path))
}

/// The worker thread's body: open the camera with `open`, then serve commands and captures.
pub(super) fn run<B: CameraSdk>(
    open: impl FnOnce() -> Result<B, OrbbecError>,
    options: OrbbecOptions,
    shared: std::sync::Arc<Shared>,
    commands: Receiver<Command>,
    ready: Sender<Result<Opened, OrbbecError>>,
) {
    let opened = open().and_then(|mut cam| {
        let identity = cam.identity()?;
        let (saved, found, path) = save_state(&mut cam, &identity.serial, &options)?;
        Ok((cam, Opened { identity, found }, saved, path))
    });
    let (cam, saved, marker, serial, restore_pending) = match opened {
        Ok((cam, opened, saved, path)) => {
            let serial = opened.identity.serial.clone();
            let pending = opened.found.leftover.is_some();
            let _ = ready.send(Ok(opened));
            (cam, saved, path, serial, pending)
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    let slack_ns = u64::try_from(options.pairing_slack.as_nanos()).unwrap_or(u64::MAX);
    let pairing = Pairing::new(options.trigger_queue, slack_ns);
    let mut w = Worker {
        cam,
        saved,
        marker,
        serial,
        restore_pending,
        restore_tried_on_fault: false,
        options,
        shared,
        state: State::Opened,
        pairing,
        consecutive_missed: 0,
        last_bad: None,
    };
    loop {
        if w.shared.faulted() && !w.restore_tried_on_fault {
            // A fault ends the streaming for good: give the camera its configuration back now
            // (an unplugged camera cannot take it: its state file stays for the next open).
            w.restore_tried_on_fault = true;
            let _ = w.restore();
        }
        let streaming = matches!(w.state, State::Streaming(_)) && !w.shared.faulted();
        let cmd = if streaming {
            match w.commands_try(&commands) {
                Some(c) => Some(c),
                None => {
                    w.stream_once();
                    continue;
                }
            }
        } else {
            match commands.recv_timeout(Duration::from_millis(u64::from(POLL_MS))) {
                Ok(c) => Some(c),
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => Some(Command::Shutdown),
            }
        };
        match cmd {
            Some(Command::Configure(c, reply)) => {
                let _ = reply.send(w.configure(&c));
            }
            Some(Command::Arm(reply)) => {
                let r = w.arm();
                if r.is_ok() {
                    w.shared.armed.store(true, Ordering::Release);
                }
                let _ = reply.send(r);
            }
            Some(Command::Close(reply)) => {
                let _ = reply.send(w.restore());
            }
            Some(Command::Shutdown) => {
                let _ = w.restore();
                return;
            }
            None => {}
        }
    }
}

impl<B> Worker<B> {
    fn commands_try(&self, commands: &Receiver<Command>) -> Option<Command> {
        match commands.try_recv() {
            Ok(c) => Some(c),
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Disconnected) => Some(Command::Shutdown),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fresh_monotonic_stamp_maps_to_about_now() {
        let clock = MonotonicClock::new();
        std::thread::sleep(Duration::from_millis(5));
        let Ok(now) = clock_gettime(ClockId::CLOCK_MONOTONIC) else { panic!("CLOCK_MONOTONIC") };
        let now_us = u64::try_from(now.tv_sec()).unwrap_or(0) * 1_000_000
            + u64::try_from(now.tv_nsec()).unwrap_or(0) / 1000;
        // A frame stamped 2 ms ago on CLOCK_MONOTONIC.
        let mapped = host_ns(now_us - 2000, true, &clock);
        let expect = clock.now_ns().saturating_sub(2_000_000);
        assert!(mapped.abs_diff(expect) < 1_000_000, "mapped {mapped} vs {expect}");
    }
}
