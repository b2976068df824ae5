//! The Orbbec worker thread: owns the SDK session, configures streams, arms software triggering,
//! and turns each capture request into one frameset converted to an [`RgbdFrame`].

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use crossbeam_queue::ArrayQueue;
use hitl_hal::{
    CaptureRequest, Clock, ErrorKind, Intrinsics, MonotonicClock, RgbdFrame, StreamConfig,
};
use nix::time::{clock_gettime, ClockId};

use super::error::OrbbecError;
use super::ffi::{
    Context, Device, Frame, Pipeline, Profile, Sdk, OB_FORMAT_RGB, OB_FORMAT_Y16,
    OB_MULTI_DEVICE_SYNC_MODE_SOFTWARE_TRIGGERING, OB_SENSOR_COLOR, OB_SENSOR_DEPTH,
};
use super::{FrameQueue, OrbbecInfo, OrbbecOptions};

/// Requests from the handle that need an answer (never sent from the tick).
pub(super) enum Command {
    Configure(StreamConfig, Sender<Result<Intrinsics, OrbbecError>>),
    Arm(Sender<Result<(), OrbbecError>>),
    Shutdown,
}

/// State shared by the tick-side handle and the worker: lock-free queues and a sticky fault.
pub(super) struct Shared {
    pub frames: FrameQueue,
    triggers: ArrayQueue<CaptureRequest>,
    armed: AtomicBool,
    /// 0 = healthy, else `1 + ErrorKind index` of the fault (readable without locks).
    fault_kind: AtomicU8,
    pub fault: OnceLock<OrbbecError>,
    dropped: AtomicU64,
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

    pub fn push_trigger(&self, request: CaptureRequest) -> Result<(), OrbbecError> {
        if !self.armed.load(Ordering::Acquire) {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: trigger before arm_trigger",
            ));
        }
        self.triggers.push(request).map_err(|_| {
            OrbbecError::new(ErrorKind::DeviceFault, "Orbbec camera: capture queue is full")
        })
    }

    pub fn frames_dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// The open SDK objects. Field order is drop order: pipeline and profiles before the device,
/// the device before the context.
struct Session {
    pipeline: Pipeline,
    color: Option<Profile>,
    depth: Option<Profile>,
    device: Device,
    _context: Context,
    monotonic: bool,
    global_timestamps: bool,
    intrinsics: Option<Intrinsics>,
    name: String,
}

fn sdk_version(sdk: &Sdk) -> String {
    let (a, b, c) = sdk.version();
    format!("{a}.{b}.{c}")
}

fn open_session(options: &OrbbecOptions) -> Result<(Session, OrbbecInfo), OrbbecError> {
    let path: &Path = &options.library;
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
    let version = sdk_version(&sdk);
    let _ = sdk.quiet_logs();
    let context =
        Context::new(&sdk).map_err(|e| OrbbecError::sdk("creating the SDK context", &e))?;
    let monotonic = context.use_monotonic_timestamps().is_ok();
    let list = context.devices().map_err(|e| OrbbecError::sdk("listing devices", &e))?;
    let count = list.count().map_err(|e| OrbbecError::sdk("counting devices", &e))?;
    if count == 0 {
        return Err(OrbbecError::new(
            ErrorKind::NotFound,
            format!(
                "no Orbbec camera found: Orbbec SDK {version} ({}) sees no device; connect the \
                 Orbbec camera (USB 3) and install its udev rules",
                path.display()
            ),
        ));
    }
    if options.device_index >= count {
        return Err(OrbbecError::new(
            ErrorKind::NotFound,
            format!(
                "Orbbec camera #{} not found: the Orbbec SDK sees {count} camera(s)",
                options.device_index
            ),
        ));
    }
    let device = list
        .device(options.device_index)
        .map_err(|e| OrbbecError::sdk("opening the Orbbec camera", &e))?;
    drop(list);
    let (name, serial) =
        device.describe().map_err(|e| OrbbecError::sdk("reading device info", &e))?;
    let pipeline =
        Pipeline::new(&device).map_err(|e| OrbbecError::sdk("creating the pipeline", &e))?;
    let info = OrbbecInfo { name: name.clone(), serial, sdk_version: version };
    let session = Session {
        pipeline,
        color: None,
        depth: None,
        device,
        _context: context,
        monotonic,
        global_timestamps: false,
        intrinsics: None,
        name,
    };
    Ok((session, info))
}

impl Session {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, OrbbecError> {
        let (w, h) = (config.intrinsics.width, config.intrinsics.height);
        let color =
            self.pipeline.video_profile(OB_SENSOR_COLOR, w, h, OB_FORMAT_RGB).map_err(|e| {
                OrbbecError::new(
                    ErrorKind::InvalidRequest,
                    format!("Orbbec camera {} has no RGB colour stream at {w}x{h}: {e}", self.name),
                )
            })?;
        let depth =
            self.pipeline.video_profile(OB_SENSOR_DEPTH, 0, 0, OB_FORMAT_Y16).map_err(|e| {
                OrbbecError::new(
                    ErrorKind::InvalidRequest,
                    format!("Orbbec camera {} has no Y16 depth stream: {e}", self.name),
                )
            })?;
        let k = color.intrinsic().map_err(|e| OrbbecError::sdk("reading colour intrinsics", &e))?;
        let (pw, ph) = color.size().map_err(|e| OrbbecError::sdk("reading colour size", &e))?;
        let intrinsics = Intrinsics {
            width: pw,
            height: ph,
            fx: f64::from(k.fx),
            fy: f64::from(k.fy),
            cx: f64::from(k.cx),
            cy: f64::from(k.cy),
        };
        self.color = Some(color);
        self.depth = Some(depth);
        self.intrinsics = Some(intrinsics);
        Ok(intrinsics)
    }

    fn arm(&mut self) -> Result<(), OrbbecError> {
        let (Some(color), Some(depth)) = (&self.color, &self.depth) else {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                "Orbbec camera: arm_trigger before configure",
            ));
        };
        let modes =
            self.device.sync_modes().map_err(|e| OrbbecError::sdk("reading sync modes", &e))?;
        if i32::from(modes) & OB_MULTI_DEVICE_SYNC_MODE_SOFTWARE_TRIGGERING == 0 {
            return Err(OrbbecError::new(
                ErrorKind::InvalidRequest,
                format!("Orbbec camera {} does not support software triggering", self.name),
            ));
        }
        let mut sync =
            self.device.sync_config().map_err(|e| OrbbecError::sdk("reading sync config", &e))?;
        sync.sync_mode = OB_MULTI_DEVICE_SYNC_MODE_SOFTWARE_TRIGGERING;
        sync.frames_per_trigger = 1;
        sync.trigger_to_image_delay_us = 0;
        sync.depth_delay_us = 0;
        sync.color_delay_us = 0;
        // Optional: cameras without global timestamps fall back to arrival times.
        self.global_timestamps = self.device.enable_global_timestamps().unwrap_or(false);
        self.device
            .set_sync_config(&sync)
            .map_err(|e| OrbbecError::sdk("setting software-trigger mode", &e))?;
        self.pipeline
            .start(color, depth)
            .map_err(|e| OrbbecError::sdk("starting colour + depth streams", &e))
    }

    fn capture(
        &mut self,
        request: CaptureRequest,
        options: &OrbbecOptions,
    ) -> Result<RgbdFrame, OrbbecError> {
        self.device.trigger_capture().map_err(|e| OrbbecError::sdk("software trigger", &e))?;
        let ms = u32::try_from(options.frame_timeout.as_millis()).unwrap_or(u32::MAX);
        let set = self
            .pipeline
            .wait_frameset(ms)
            .map_err(|e| OrbbecError::sdk("waiting for a frameset", &e))?
            .ok_or_else(|| {
                OrbbecError::new(
                    ErrorKind::Timeout,
                    format!(
                        "Orbbec camera: no frameset within {ms} ms of the software trigger for tick {}",
                        request.tick
                    ),
                )
            })?;
        let color =
            set.color().map_err(|e| OrbbecError::sdk("colour frame", &e))?.ok_or_else(|| {
                OrbbecError::new(ErrorKind::DeviceFault, "Orbbec camera: frameset without colour")
            })?;
        let depth =
            set.depth().map_err(|e| OrbbecError::sdk("depth frame", &e))?.ok_or_else(|| {
                OrbbecError::new(ErrorKind::DeviceFault, "Orbbec camera: frameset without depth")
            })?;
        let intrinsics = self.intrinsics.ok_or_else(|| {
            OrbbecError::new(ErrorKind::InvalidRequest, "Orbbec camera: capture before configure")
        })?;
        let (device_us, system_us, global_us) =
            color.timestamps_us().map_err(|e| OrbbecError::sdk("frame timestamps", &e))?;
        // Exposure on the host clock where the camera can say it; else the arrival time, which
        // is later than the exposure by the transfer time.
        let host_us = if self.global_timestamps && global_us != 0 { global_us } else { system_us };
        Ok(RgbdFrame {
            request,
            device_ns: device_us.saturating_mul(1000),
            exposure_ns: host_ns(host_us, self.monotonic, &options.clock),
            intrinsics,
            color: color_rgb8(&color, intrinsics)?,
            depth_m: depth_metres(&depth, intrinsics)?,
            mask: None,
        })
    }
}

/// Map an SDK system timestamp (CLOCK_MONOTONIC or CLOCK_REALTIME, µs) onto `clock`.
fn host_ns(system_us: u64, monotonic: bool, clock: &MonotonicClock) -> u64 {
    let id = if monotonic { ClockId::CLOCK_MONOTONIC } else { ClockId::CLOCK_REALTIME };
    let Ok(now) = clock_gettime(id) else {
        return clock.now_ns();
    };
    let now_ns = u64::try_from(now.tv_sec()).unwrap_or(0).saturating_mul(1_000_000_000)
        + u64::try_from(now.tv_nsec()).unwrap_or(0);
    let age_ns = now_ns.saturating_sub(system_us.saturating_mul(1000));
    clock.now_ns().saturating_sub(age_ns)
}

fn bad_frame(what: String) -> OrbbecError {
    OrbbecError::new(ErrorKind::DeviceFault, format!("Orbbec camera: {what}"))
}

fn color_rgb8(frame: &Frame, k: Intrinsics) -> Result<Vec<u8>, OrbbecError> {
    let fmt = frame.format().map_err(|e| OrbbecError::sdk("colour format", &e))?;
    if fmt != OB_FORMAT_RGB {
        return Err(bad_frame(format!("colour frame has format {fmt}, expected RGB (22)")));
    }
    let (w, h) = frame.size().map_err(|e| OrbbecError::sdk("colour size", &e))?;
    let data = frame.data().map_err(|e| OrbbecError::sdk("colour data", &e))?;
    let want = (w as usize) * (h as usize) * 3;
    if (w, h) != (k.width, k.height) || data.len() < want {
        return Err(bad_frame(format!(
            "colour frame {w}x{h} with {} bytes does not match {}x{} rgb8",
            data.len(),
            k.width,
            k.height
        )));
    }
    Ok(data[..want].to_vec())
}

fn depth_metres(frame: &Frame, k: Intrinsics) -> Result<Vec<f32>, OrbbecError> {
    let fmt = frame.format().map_err(|e| OrbbecError::sdk("depth format", &e))?;
    if fmt != OB_FORMAT_Y16 {
        return Err(bad_frame(format!("depth frame has format {fmt}, expected Y16 (8)")));
    }
    let (w, h) = frame.size().map_err(|e| OrbbecError::sdk("depth size", &e))?;
    let scale_mm = frame.depth_scale_mm().map_err(|e| OrbbecError::sdk("depth scale", &e))?;
    let data = frame.data().map_err(|e| OrbbecError::sdk("depth data", &e))?;
    let n = (w as usize) * (h as usize);
    if (w, h) != (k.width, k.height)
        || data.len() < n * 2
        || !scale_mm.is_finite()
        || scale_mm <= 0.0
    {
        return Err(bad_frame(format!(
            "depth frame {w}x{h} ({} bytes, scale {scale_mm} mm) is not aligned to colour {}x{}",
            data.len(),
            k.width,
            k.height
        )));
    }
    Ok(y16_to_metres(&data[..n * 2], scale_mm))
}

/// Little-endian 16-bit depth units to metres (`scale_mm` millimetres per unit; 0 stays 0).
fn y16_to_metres(data: &[u8], scale_mm: f32) -> Vec<f32> {
    let to_m = scale_mm / 1000.0;
    data.chunks_exact(2).map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) * to_m).collect()
}

/// The worker thread's body.
pub(super) fn run(
    options: OrbbecOptions,
    shared: Arc<Shared>,
    commands: Receiver<Command>,
    ready: Sender<Result<OrbbecInfo, OrbbecError>>,
) {
    let mut session = match open_session(&options) {
        Ok((s, info)) => {
            let _ = ready.send(Ok(info));
            s
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    loop {
        match commands.recv_timeout(Duration::from_millis(1)) {
            Ok(Command::Configure(c, reply)) => {
                let _ = reply.send(session.configure(&c));
            }
            Ok(Command::Arm(reply)) => {
                let r = session.arm();
                if r.is_ok() {
                    shared.armed.store(true, Ordering::Release);
                }
                let _ = reply.send(r);
            }
            Ok(Command::Shutdown) | Err(RecvTimeoutError::Disconnected) => return,
            Err(RecvTimeoutError::Timeout) => {}
        }
        if shared.fault.get().is_some() {
            continue;
        }
        while let Some(req) = shared.triggers.pop() {
            match session.capture(req, &options) {
                Ok(frame) => {
                    if shared.frames.force_push(frame).is_some() {
                        shared.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(e) => {
                    shared.trip(e);
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_units_become_metres() {
        let data = [0x00, 0x00, 0xE8, 0x03, 0x10, 0x27];
        assert_eq!(y16_to_metres(&data, 1.0), vec![0.0, 1.0, 10.0]);
        let half = y16_to_metres(&data, 0.5);
        assert!((half[1] - 0.5).abs() < 1e-6);
    }

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
