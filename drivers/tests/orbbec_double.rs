//! The Orbbec driver's state machine on a scripted double of the SDK surface ([`CameraSdk`]):
//! configure -> arm -> trigger -> frames, in hardware and software triggering, and what happens
//! on stale framesets (older than their trigger), missed ones, a full capture queue, refused
//! metadata and an unplugged camera; and the camera left as found: the sync configuration and
//! settings found at open written back at close, on drop and after a fault, a crashed run's
//! state file noticed and its configuration written back. No camera and no SDK library needed.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_channel::{unbounded, Receiver, Sender};
use hitl_drivers::orbbec::sync::{mode_names, MODE_FREE_RUN, MODE_HARDWARE_TRIGGERING};
use hitl_drivers::orbbec::{
    marker, sdk_clock_now_us, CameraIdentity, CameraSdk, FrameMeta, OrbbecCamera, OrbbecError,
    OrbbecOptions, RawFrameset, RawImage, SavedState, Setting, Stream, SyncConfig, TriggerChoice,
    TriggerMode, VideoProfile,
};
use hitl_hal::{
    CaptureRequest, Clock, Error, ErrorKind, Intrinsics, Lifecycle, MonotonicClock, RgbdCamera,
    RgbdFrame, StreamConfig, TimestampSource,
};

const W: u32 = 8;
const H: u32 = 6;

enum Step {
    Frames(RawFrameset),
    Fail(OrbbecError),
    /// Block in `wait_frameset` this long (a slow SDK call), then time out.
    Stall(Duration),
}

/// What the double's camera keeps across opens (as a camera keeps its configuration).
#[derive(Debug, Clone, PartialEq)]
struct DeviceState {
    sync: SyncConfig,
    exposure_reference: i32,
    sync_voltage_level: i32,
}

/// The camera as it leaves the factory, trigger out on (as Orbbec's examples set it).
fn factory() -> DeviceState {
    DeviceState {
        sync: SyncConfig {
            mode: MODE_FREE_RUN,
            depth_delay_us: 0,
            color_delay_us: 0,
            trigger_to_image_delay_us: 0,
            trigger_out_enable: true,
            trigger_out_delay_us: 0,
            frames_per_trigger: 1,
        },
        exposure_reference: 0,
        sync_voltage_level: 0,
    }
}

struct Double {
    pid: u16,
    global: bool,
    steps: Receiver<Step>,
    log: Arc<Mutex<Vec<String>>>,
    device: Arc<Mutex<DeviceState>>,
}

impl Double {
    fn note(&self, s: String) {
        self.log.lock().expect("log").push(s);
    }
}

fn intrinsics() -> Intrinsics {
    Intrinsics {
        width: W,
        height: H,
        fx: 10.0,
        fy: 10.0,
        cx: 4.0,
        cy: 3.0,
        distortion: Default::default(),
    }
}

impl CameraSdk for Double {
    fn identity(&mut self) -> Result<CameraIdentity, OrbbecError> {
        Ok(CameraIdentity {
            name: "Orbbec Gemini 305 (double)".into(),
            serial: "CP0000000001".into(),
            product_id: self.pid,
            firmware: "1.0.80".into(),
            sdk_version: "2.9.3".into(),
        })
    }
    fn profiles(&mut self, stream: Stream) -> Result<Vec<VideoProfile>, OrbbecError> {
        let p = |width, height, format, fps| VideoProfile { width, height, format, fps };
        Ok(match stream {
            Stream::Color => vec![p(W, H, 22, 60), p(W, H, 22, 30), p(W, H, 5, 30)],
            Stream::Depth => vec![p(4, 3, 8, 60), p(16, 12, 8, 30), p(4, 3, 8, 30)],
        })
    }
    fn intrinsics(&mut self, _color: VideoProfile) -> Result<Intrinsics, OrbbecError> {
        Ok(intrinsics())
    }
    fn advertised_sync_modes(&mut self) -> Result<u16, OrbbecError> {
        Ok(0x7F) // everything, as 2.9.3 does for the whole family
    }
    fn sync_config(&mut self) -> Result<SyncConfig, OrbbecError> {
        Ok(self.device.lock().expect("device").sync)
    }
    fn set_sync_config(&mut self, config: &SyncConfig) -> Result<(), OrbbecError> {
        self.note(format!(
            "sync {} out {}",
            mode_names(config.mode),
            if config.trigger_out_enable { "on" } else { "off" }
        ));
        self.device.lock().expect("device").sync = *config;
        Ok(())
    }
    fn get(&mut self, setting: Setting) -> Result<Option<i32>, OrbbecError> {
        let d = self.device.lock().expect("device");
        Ok(match setting {
            Setting::ExposureReference => Some(d.exposure_reference),
            // Firmware older than 1.0.76 has no sync voltage property.
            Setting::SyncVoltageLevel if self.pid == 0x0841 => None,
            Setting::SyncVoltageLevel => Some(d.sync_voltage_level),
        })
    }
    fn set(&mut self, setting: Setting, value: i32) -> Result<bool, OrbbecError> {
        // Firmware older than 1.0.76 has no sync voltage property.
        if setting == Setting::SyncVoltageLevel && self.pid == 0x0841 {
            return Ok(false);
        }
        self.note(format!("set {setting:?} {value}"));
        let mut d = self.device.lock().expect("device");
        match setting {
            Setting::ExposureReference => d.exposure_reference = value,
            Setting::SyncVoltageLevel => d.sync_voltage_level = value,
        }
        Ok(true)
    }
    fn stop(&mut self) -> Result<(), OrbbecError> {
        self.note("stop".into());
        Ok(())
    }
    fn enable_global_timestamps(&mut self) -> Result<bool, OrbbecError> {
        Ok(self.global)
    }
    fn monotonic_stamps(&self) -> bool {
        true
    }
    fn start(&mut self, color: VideoProfile, depth: VideoProfile) -> Result<(), OrbbecError> {
        self.note(format!("start {color} + {depth}"));
        Ok(())
    }
    fn software_trigger(&mut self) -> Result<(), OrbbecError> {
        self.note("software trigger".into());
        Ok(())
    }
    fn wait_frameset(&mut self, timeout_ms: u32) -> Result<Option<RawFrameset>, OrbbecError> {
        match self.steps.recv_timeout(Duration::from_millis(u64::from(timeout_ms))) {
            Ok(Step::Frames(f)) => Ok(Some(f)),
            Ok(Step::Fail(e)) => Err(e),
            Ok(Step::Stall(d)) => {
                self.note("stalling".into());
                std::thread::sleep(d);
                Ok(None)
            }
            Err(_) => Ok(None),
        }
    }
}

struct Rig {
    cam: OrbbecCamera,
    steps: Sender<Step>,
    log: Arc<Mutex<Vec<String>>>,
    clock: MonotonicClock,
    device: Arc<Mutex<DeviceState>>,
    state_dir: tempfile::TempDir,
}

impl Rig {
    fn device(&self) -> DeviceState {
        self.device.lock().expect("device").clone()
    }
    fn marker(&self) -> std::path::PathBuf {
        marker::marker_path(self.state_dir.path(), "CP0000000001")
    }
}

fn rig_with(pid: u16, global: bool, tune: impl FnOnce(&mut OrbbecOptions)) -> Rig {
    let state_dir = tempfile::tempdir().expect("state dir");
    rig_on(pid, global, Arc::new(Mutex::new(factory())), state_dir, tune)
}

/// A rig on the camera `device` (kept across opens), with its state files in `state_dir`.
fn rig_on(
    pid: u16,
    global: bool,
    device: Arc<Mutex<DeviceState>>,
    state_dir: tempfile::TempDir,
    tune: impl FnOnce(&mut OrbbecOptions),
) -> Rig {
    let clock = MonotonicClock::new();
    let (tx, rx) = unbounded();
    let log = Arc::new(Mutex::new(Vec::new()));
    let double =
        Double { pid, global, steps: rx, log: Arc::clone(&log), device: Arc::clone(&device) };
    let mut options = OrbbecOptions {
        clock: clock.clone(),
        frame_timeout: Duration::from_millis(60),
        state_dir: Some(state_dir.path().to_path_buf()),
        ..OrbbecOptions::default()
    };
    tune(&mut options);
    let cam = OrbbecCamera::open_with(move || Ok(double), options).expect("open the double");
    Rig { cam, steps: tx, log, clock, device, state_dir }
}

fn config() -> StreamConfig {
    StreamConfig { intrinsics: intrinsics(), mask: false }
}

fn armed(pid: u16, global: bool, tune: impl FnOnce(&mut OrbbecOptions)) -> Rig {
    let mut r = rig_with(pid, global, tune);
    assert_eq!(r.cam.configure(&config()), Ok(intrinsics()));
    r.cam.arm_trigger().expect("arm");
    r
}

/// A frameset stamped at `at_ns` on the controller's clock (as the SDK stamps: CLOCK_MONOTONIC
/// microseconds), colour filled with `mark`, depth 1.5 m (units of 1 mm).
fn frameset(r: &Rig, at_ns: u64, mark: u8, global: bool) -> RawFrameset {
    let age_ns = i128::from(r.clock.now_ns()) - i128::from(at_ns);
    let sdk_us = u64::try_from(i128::from(sdk_clock_now_us()) - age_ns / 1000).expect("stamp");
    let meta = |format, scale| FrameMeta {
        width: W,
        height: H,
        format,
        device_us: 77,
        system_us: sdk_us + 20_000, // arrives 20 ms after the exposure
        global_us: if global { sdk_us } else { 0 },
        depth_scale_mm: scale,
    };
    let depth: Vec<u8> = (0..W * H).flat_map(|_| 1500u16.to_le_bytes()).collect();
    RawFrameset {
        color: Some(RawImage { meta: meta(22, 0.0), data: vec![mark; (W * H * 3) as usize] }),
        depth: Some(RawImage { meta: meta(8, 1.0), data: depth }),
    }
}

fn fire(r: &mut Rig, tick: u64) -> CaptureRequest {
    let req = CaptureRequest { tick, fired_ns: r.clock.now_ns() };
    r.cam.trigger(req).expect("trigger");
    req
}

/// Poll like the tick does until a frame comes or `within` passes.
fn next_frame(r: &mut Rig, within: Duration) -> Result<Option<RgbdFrame>, OrbbecError> {
    let end = Instant::now() + within;
    while Instant::now() < end {
        if let Some(f) = r.cam.poll_frame()? {
            return Ok(Some(f));
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    Ok(None)
}

fn log(r: &Rig) -> Vec<String> {
    r.log.lock().expect("log").clone()
}

#[test]
fn a_hardware_triggered_frame_comes_back_paired_and_in_metres() {
    // Room for a loaded machine between the trigger and the frame (expiry is not tested here).
    let mut r = armed(0x0842, true, |o| o.frame_timeout = Duration::from_secs(1));
    assert_eq!(r.cam.trigger_mode(), Some(TriggerMode::Hardware));
    let armed = r.cam.armed().expect("armed");
    assert!(armed.exposure_reference_middle && armed.global_timestamps);
    assert_eq!((armed.color.fps, armed.depth.fps), (30, 30), "one frame rate for both");
    assert_eq!(
        log(&r),
        vec![
            // Trigger out set explicitly (off: nothing is chained), whatever the camera had.
            "sync hardware-triggering out off".to_string(),
            "set ExposureReference 1".into(),
            // One frame rate for both (30, preferred), depth of the colour's size absent: the
            // largest depth at 30 fps.
            "start 8x6 RGB(22) @30 fps + 16x12 Y16(8) @30 fps".into(),
        ]
    );
    let req = fire(&mut r, 7);
    let exposed = req.fired_ns + 1_000_000;
    std::thread::sleep(Duration::from_millis(2)); // stamps from the past, as the SDK's are
    r.steps.send(Step::Frames(frameset(&r, exposed, 9, true))).expect("send");
    let f = next_frame(&mut r, Duration::from_secs(2)).expect("healthy").expect("a frame");
    assert_eq!(f.request, req);
    assert_eq!(f.timestamp, TimestampSource::DeviceExposure);
    // Within the two clocks' reading jitter (5 ms allows a loaded CI box; the arrival is 20 ms).
    assert!(f.exposure_ns.abs_diff(exposed) < 5_000_000, "{} vs {exposed}", f.exposure_ns);
    assert_eq!(f.device_ns, 77_000);
    assert_eq!(f.intrinsics, intrinsics());
    assert!(f.color.iter().all(|b| *b == 9) && f.color.len() == 144);
    assert!(f.depth_m.iter().all(|d| (*d - 1.5).abs() < 1e-6) && f.depth_m.len() == 48);
    assert!(!log(&r).contains(&"software trigger".to_string()), "hardware mode fires nothing");
    assert_eq!((r.cam.frames_missed(), r.cam.frames_stale()), (0, 0));
}

#[test]
fn without_global_timestamps_the_frame_says_it_carries_its_arrival_time() {
    let mut r = armed(0x0840, false, |o| {
        o.trigger = TriggerChoice::Software;
        o.frame_timeout = Duration::from_secs(1); // the 25 ms sleep may overshoot under load
    });
    let req = fire(&mut r, 3);
    std::thread::sleep(Duration::from_millis(25)); // the frameset arrives 21 ms after the trigger
    r.steps.send(Step::Frames(frameset(&r, req.fired_ns + 1_000_000, 1, false))).expect("send");
    let f = next_frame(&mut r, Duration::from_secs(2)).expect("healthy").expect("a frame");
    assert_eq!(f.request.tick, 3);
    assert_eq!(f.timestamp, TimestampSource::HostArrival);
    // The arrival, 20 ms after the exposure.
    let arrival = req.fired_ns + 21_000_000;
    assert!(f.exposure_ns.abs_diff(arrival) < 5_000_000, "{} vs {arrival}", f.exposure_ns);
    assert_eq!(log(&r)[0], "sync software-triggering out off");
    assert_eq!(log(&r).iter().filter(|l| *l == "software trigger").count(), 1);
}

#[test]
fn arm_before_configure_is_refused_and_the_right_order_works() {
    let mut r = rig_with(0x0840, true, |_| {});
    let e = r.cam.arm_trigger().expect_err("not configured");
    assert_eq!(e.kind(), ErrorKind::InvalidRequest);
    assert!(e.message().contains("arm_trigger before configure"), "{e}");
    let e = r.cam.trigger(CaptureRequest { tick: 1, fired_ns: 1 }).expect_err("not armed");
    assert_eq!(e.kind(), ErrorKind::InvalidRequest);
    assert_eq!(r.cam.configure(&config()), Ok(intrinsics()));
    r.cam.arm_trigger().expect("arm after configure");
    let e = r.cam.configure(&config()).expect_err("streams are running");
    assert_eq!(e.kind(), ErrorKind::InvalidRequest);
    // A camera still healthy after the refusals.
    assert_eq!(r.cam.poll_frame(), Ok(None));
}

#[test]
fn the_305g_is_never_software_triggered_even_though_the_sdk_advertises_it() {
    let mut r = rig_with(0x0842, true, |o| o.trigger = TriggerChoice::Software);
    r.cam.configure(&config()).expect("configure");
    let e = r.cam.arm_trigger().expect_err("undocumented mode");
    assert_eq!(e.kind(), ErrorKind::InvalidRequest);
    assert!(e.message().contains("Gemini 305g"), "{e}");
    assert!(log(&r).is_empty(), "nothing was set on the camera: {:?}", log(&r));
}

#[test]
fn a_frame_older_than_its_trigger_is_stale_and_the_trigger_is_missed_not_a_fault() {
    let mut r = armed(0x0840, true, |_| {});
    std::thread::sleep(Duration::from_millis(10)); // the controller clock starts at 0
    let first = fire(&mut r, 1);
    // Exposed 5 ms BEFORE the trigger fired: not this trigger's frame.
    r.steps.send(Step::Frames(frameset(&r, first.fired_ns - 5_000_000, 1, true))).expect("send");
    let end = Instant::now() + Duration::from_secs(5);
    // Stale is counted when the frameset is read, missed when the trigger expires: wait for both.
    while (r.cam.frames_missed() == 0 || r.cam.frames_stale() == 0) && Instant::now() < end {
        assert_eq!(r.cam.poll_frame(), Ok(None), "no frame for trigger 1, and no fault");
        std::thread::sleep(Duration::from_millis(2));
    }
    assert_eq!(r.cam.frames_stale(), 1);
    assert_eq!(r.cam.frames_missed(), 1, "trigger 1 expired after frame_timeout");
    // The camera goes on: the next trigger gets its frame.
    let second = fire(&mut r, 2);
    r.steps.send(Step::Frames(frameset(&r, second.fired_ns + 500_000, 2, true))).expect("send");
    let f = next_frame(&mut r, Duration::from_secs(2)).expect("healthy").expect("a frame");
    assert_eq!((f.request, f.color[0]), (second, 2));
}

#[test]
fn a_frame_pairs_with_its_own_trigger_when_an_earlier_one_was_missed() {
    let mut r = armed(0x0840, true, |o| o.frame_timeout = Duration::from_secs(5));
    let _lost = fire(&mut r, 10);
    std::thread::sleep(Duration::from_millis(3));
    let second = fire(&mut r, 11);
    r.steps.send(Step::Frames(frameset(&r, second.fired_ns + 100_000, 11, true))).expect("send");
    let f = next_frame(&mut r, Duration::from_secs(2)).expect("healthy").expect("a frame");
    assert_eq!(f.request.tick, 11, "paired by timestamp, not by order");
    assert_eq!(r.cam.frames_missed(), 1);
}

#[test]
fn triggers_answered_by_nothing_trip_the_camera_after_the_limit() {
    let mut r = armed(0x0842, true, |o| o.max_consecutive_missed = 2);
    fire(&mut r, 1);
    fire(&mut r, 2);
    let end = Instant::now() + Duration::from_secs(2);
    let e = loop {
        match r.cam.poll_frame() {
            Err(e) => break e,
            Ok(_) if Instant::now() > end => panic!("two missed triggers must trip the camera"),
            Ok(_) => std::thread::sleep(Duration::from_millis(2)),
        }
    };
    assert_eq!(e.kind(), ErrorKind::DeviceFault);
    let detail = r.cam.fault_detail().expect("detail").message().to_string();
    assert!(detail.contains("answered none of the last 2 triggers"), "{detail}");
    assert!(detail.contains("trigger box's camera line"), "{detail}");
    // Sticky: later triggers are refused with the same kind.
    let e = r.cam.trigger(CaptureRequest { tick: 3, fired_ns: 0 }).expect_err("tripped");
    assert_eq!(e.kind(), ErrorKind::DeviceFault);
}

#[test]
fn a_full_capture_queue_is_busy_not_a_fault() {
    let mut r = armed(0x0840, true, |o| o.trigger_queue = 1);
    r.steps.send(Step::Stall(Duration::from_millis(500))).expect("send");
    let end = Instant::now() + Duration::from_secs(5);
    while !log(&r).contains(&"stalling".to_string()) {
        assert!(Instant::now() < end, "the worker never took the stall");
        std::thread::sleep(Duration::from_millis(1));
    }
    fire(&mut r, 1);
    let e =
        r.cam.trigger(CaptureRequest { tick: 2, fired_ns: r.clock.now_ns() }).expect_err("full");
    assert_eq!(e.kind(), ErrorKind::Timeout, "busy, as the tick understands it: {e}");
    assert_eq!(r.cam.poll_frame(), Ok(None), "the camera still works");
}

#[test]
fn refused_metadata_is_counted_and_named_when_the_camera_trips() {
    // The frameset must be read (and refused) before the trigger expires and trips the camera;
    // a second gives a loaded machine room for that.
    let mut r = armed(0x0840, true, |o| {
        o.max_consecutive_missed = 1;
        o.frame_timeout = Duration::from_secs(1);
    });
    let req = fire(&mut r, 1);
    let mut bad = frameset(&r, req.fired_ns + 100_000, 1, true);
    if let Some(d) = bad.depth.as_mut() {
        d.meta.width = 4; // depth not aligned to colour
    }
    r.steps.send(Step::Frames(bad)).expect("send");
    let e = next_frame(&mut r, Duration::from_secs(5)).expect_err("trips after the miss");
    assert_eq!(e.kind(), ErrorKind::DeviceFault);
    assert_eq!(r.cam.frames_refused(), 1);
    let detail = r.cam.fault_detail().expect("detail").message().to_string();
    assert!(detail.contains("not aligned to colour 8x6"), "{detail}");
}

#[test]
fn an_unplugged_camera_is_disconnected() {
    let mut r = armed(0x0840, true, |_| {});
    fire(&mut r, 1);
    let gone = OrbbecError::new(
        ErrorKind::Disconnected,
        "Orbbec camera: waiting for a frameset: unplugged",
    );
    r.steps.send(Step::Fail(gone)).expect("send");
    let e = next_frame(&mut r, Duration::from_secs(2)).expect_err("unplugged");
    assert_eq!(e.kind(), ErrorKind::Disconnected);
    assert!(r.cam.fault_detail().expect("detail").message().contains("unplugged"));
}

#[test]
fn the_sync_voltage_is_written_where_the_firmware_has_it_and_refused_where_not() {
    let r = armed(0x0840, true, |o| o.sync_voltage_level = Some(1));
    assert!(log(&r).contains(&"set SyncVoltageLevel 1".to_string()), "{:?}", log(&r));
    let mut old = rig_with(0x0841, true, |o| o.sync_voltage_level = Some(1));
    old.cam.configure(&config()).expect("configure");
    let e = old.cam.arm_trigger().expect_err("no sync voltage property");
    assert_eq!(e.kind(), ErrorKind::InvalidRequest);
    assert!(e.message().contains("firmware >= 1.0.76"), "{e}");
    assert!(!log(&old).iter().any(|l| l.starts_with("start")), "nothing started: {:?}", log(&old));
}

/// Wait until `cond` holds for the rig's camera (the worker acts on its own thread).
fn eventually(r: &Rig, what: &str, cond: impl Fn(&DeviceState) -> bool) {
    let end = Instant::now() + Duration::from_secs(5);
    while !cond(&r.device()) {
        assert!(Instant::now() < end, "{what}: {:?}, log {:?}", r.device(), log(r));
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn closing_writes_back_what_was_found_at_open_and_removes_the_state_file() {
    let mut r = armed(0x0840, true, |o| o.sync_voltage_level = Some(2));
    let armed_state = r.device();
    assert_eq!(armed_state.sync.mode, MODE_HARDWARE_TRIGGERING);
    assert!(!armed_state.sync.trigger_out_enable, "trigger out set explicitly");
    assert_eq!((armed_state.exposure_reference, armed_state.sync_voltage_level), (1, 2));
    // While the camera is changed, the state file says what it had.
    let saved = marker::read(&r.marker()).expect("readable").expect("written before the change");
    assert_eq!(saved.saved.sync, factory().sync);
    assert_eq!(r.cam.found().sync, factory().sync);
    assert_eq!(r.cam.found().warning(), None, "a camera in free-run is nothing to report");
    r.cam.stop().expect("close");
    assert_eq!(r.device(), factory(), "sync configuration and settings written back");
    assert_eq!(marker::read(&r.marker()), Ok(None), "state file removed");
    let l = log(&r);
    let stop = l.iter().position(|x| x == "stop").expect("streams stopped");
    assert!(l[stop + 1..].contains(&"sync free-run out on".to_string()), "{l:?}");
}

#[test]
fn dropping_the_camera_without_closing_writes_back_too() {
    let r = armed(0x0842, true, |_| {});
    assert_eq!(r.device().sync.mode, MODE_HARDWARE_TRIGGERING);
    let Rig { cam, device, state_dir, .. } = r;
    drop(cam);
    assert_eq!(*device.lock().expect("device"), factory());
    assert_eq!(marker::read(&marker::marker_path(state_dir.path(), "CP0000000001")), Ok(None));
}

#[test]
fn a_fault_writes_the_configuration_back_at_once() {
    let mut r = armed(0x0842, true, |o| o.max_consecutive_missed = 1);
    fire(&mut r, 1);
    // No frame: the trigger is missed and the camera trips (a run then stops).
    let e = next_frame(&mut r, Duration::from_secs(2)).expect_err("tripped");
    assert_eq!(e.kind(), ErrorKind::DeviceFault);
    eventually(&r, "written back after the fault, before any close", |d| *d == factory());
    // The worker removes the state file just after the last write back: wait for it too.
    let end = Instant::now() + Duration::from_secs(5);
    while marker::read(&r.marker()) != Ok(None) {
        assert!(Instant::now() < end, "state file left after the write back");
        std::thread::sleep(Duration::from_millis(2));
    }
    assert_eq!(r.cam.health().map_err(|e| e.kind()), Err(ErrorKind::DeviceFault));
    r.cam.stop().expect("closing a tripped camera: nothing left to write back");
}

#[test]
fn a_crashed_runs_state_file_is_reported_at_open_and_its_configuration_written_back() {
    // A run armed the camera and died: the camera waits for triggers, the state file remains.
    let crashed = armed(0x0840, true, |_| {});
    let Rig { cam, device, state_dir, .. } = crashed;
    let path = marker::marker_path(state_dir.path(), "CP0000000001");
    let left = marker::read(&path).expect("readable").expect("written");
    std::mem::forget(cam); // no close, no drop: as a killed process
    assert_eq!(device.lock().expect("device").sync.mode, MODE_HARDWARE_TRIGGERING);
    // The next open notices it...
    let mut r = rig_on(0x0840, true, Arc::clone(&device), state_dir, |_| {});
    let found = r.cam.found().clone();
    assert_eq!(found.sync.mode, MODE_HARDWARE_TRIGGERING, "what the camera holds now");
    assert_eq!(found.leftover.as_ref().map(|l| &l.saved), Some(&left.saved));
    let warning = found.warning().expect("reported");
    assert!(warning.contains("ended without writing the camera's configuration back"), "{warning}");
    assert!(warning.contains("CP0000000001.sync"), "{warning}");
    // ...and its close writes back what the camera had before the crashed run, not what it found.
    r.cam.stop().expect("close");
    assert_eq!(r.device(), factory());
    assert_eq!(marker::read(&r.marker()), Ok(None));
}

#[test]
fn a_camera_waiting_for_triggers_with_no_record_is_reported_and_left_so() {
    let mut state = factory();
    state.sync.mode = MODE_HARDWARE_TRIGGERING;
    let device = Arc::new(Mutex::new(state.clone()));
    let mut r = rig_on(0x0840, true, device, tempfile::tempdir().expect("dir"), |_| {});
    let warning = r.cam.found().warning().expect("reported");
    assert!(warning.contains("no record of a hitl run"), "{warning}");
    r.cam.configure(&config()).expect("configure");
    r.cam.arm_trigger().expect("arm");
    r.cam.stop().expect("close");
    assert_eq!(r.device(), state, "written back as found");
}

#[test]
fn the_state_file_holds_what_the_camera_had_before_the_run() {
    let r = armed(0x0840, true, |_| {});
    let text = std::fs::read_to_string(r.marker()).expect("state file");
    assert!(text.contains("serial=CP0000000001"), "{text}");
    assert!(text.contains(&format!("sync_mode={MODE_FREE_RUN}")), "{text}");
    assert!(text.contains("trigger_out_enable=1"), "{text}");
    let back = marker::read(&r.marker()).expect("ok").expect("there");
    assert_eq!(
        back.saved,
        SavedState {
            sync: factory().sync,
            settings: vec![(Setting::ExposureReference, 0), (Setting::SyncVoltageLevel, 0)],
        }
    );
    let _ = TriggerMode::Hardware;
}
