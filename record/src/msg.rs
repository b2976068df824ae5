//! The messages a run records: plain data the tick and the camera intake hand to the recorder.
//!
//! Telemetry messages are `Copy` (or, for safety events raised from the tick, free of heap data)
//! so the real-time tick can push them into bounded lock-free queues without allocating. Frames
//! carry their pixel buffers and are built outside the tick by the camera intake.

use hitl_hal::{ArmState, CaptureRequest, Intrinsics, Pose, RgbdFrame, SharedPixels, DOF};
use serde::{Deserialize, Serialize};

/// Which part of a run a setpoint belongs to: the hal's one [`Phase`]. `/arm/setpoint` never
/// holds [`Phase::Settle`] (it is recorded as playback, [`Phase::recorded`]).
pub use hitl_hal::Phase;

/// `/arm/setpoint`: the setpoint the tick sent to the arm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SetpointMsg {
    pub tick: u64,
    /// Host monotonic time of the tick, nanoseconds.
    pub t_ns: u64,
    pub phase: Phase,
    /// Joint positions, radians.
    pub q: [f64; DOF],
    /// Joint velocities, radians per second.
    pub qd: [f64; DOF],
}

/// `/arm/state`: one report of the arm as measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ArmStateMsg {
    /// Host monotonic time the report was received, nanoseconds.
    pub t_ns: u64,
    pub q: [f64; DOF],
    pub state: u8,
    pub mode: u8,
    pub error_code: u16,
    pub warn_code: u16,
}

impl From<&ArmState> for ArmStateMsg {
    fn from(s: &ArmState) -> Self {
        Self {
            t_ns: s.received_ns,
            q: s.q,
            state: s.state,
            mode: s.mode,
            error_code: u16::from(s.error_code),
            warn_code: u16::from(s.warn_code),
        }
    }
}

/// `/loop/timing`: how late the tick woke and how long it took.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimingMsg {
    pub tick: u64,
    /// Host monotonic time the tick woke, nanoseconds (the message's log time).
    pub t_ns: u64,
    /// Wake-up time minus the tick's deadline, nanoseconds (negative: early).
    pub wake_late_ns: i64,
    /// Time the tick's work took, nanoseconds.
    pub tick_ns: u64,
    /// The tick missed its period.
    pub overrun: bool,
}

/// `/camera/sync`: when a capture was triggered, when it was exposed, and the difference (the
/// hard sync's error; positive when the exposure came after the trigger). Host monotonic ns.
/// With the light level in effect at the exposure (0..1), where the run drove a light.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CaptureSyncMsg {
    pub tick: u64,
    pub trigger_ns: u64,
    pub exposure_ns: u64,
    pub sync_error_ns: i64,
    /// The level the light was at for this exposure: the trajectory's level at the capture's
    /// tick, which went out `[light] lead_ms` earlier so the lamp shows it at the exposure
    /// (docs/lights.md). Absent in recordings made before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_level: Option<f32>,
}

impl CaptureSyncMsg {
    pub fn new(tick: u64, trigger_ns: u64, exposure_ns: u64) -> Self {
        let sync_error_ns = Self::error_ns(trigger_ns, exposure_ns);
        CaptureSyncMsg { tick, trigger_ns, exposure_ns, sync_error_ns, light_level: None }
    }

    /// The sync error: exposure minus trigger, nanoseconds (the one definition, also used for the
    /// run summary's figures).
    pub fn error_ns(trigger_ns: u64, exposure_ns: u64) -> i64 {
        (exposure_ns as i64).saturating_sub(trigger_ns as i64)
    }
}

/// `/light/state`: the lab light's commanded level.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LightMsg {
    pub t_ns: u64,
    /// Level in [0, 1].
    pub level: f32,
}

/// `/trigger/fired`: a trigger-line fire the trigger box acknowledged, with the time it says it
/// fired on its own clock (the exposure's start for a hardware-triggered camera) and that time on
/// the host's clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerFiredMsg {
    /// Host monotonic time the acknowledgement arrived, nanoseconds.
    pub t_ns: u64,
    /// The tick the fire was asked for.
    pub tick: u64,
    /// When the box fired, on its clock, microseconds.
    pub device_us: u64,
    /// When the box fired on the host's monotonic clock, nanoseconds: `device_us` through the
    /// driver's clock mapping (absent in recordings made before it, or before a mapping existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fired_ns: Option<u64>,
    /// A bound on `fired_ns`'s error, nanoseconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clock_error_ns: Option<u64>,
}

/// What happened, in the words of the safety case. Written as kebab-case strings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EventKind {
    /// Command/measured deviation beyond its limit.
    Deviation,
    /// The arm's report stream went quiet.
    ReportWatchdog,
    /// The arm reported an error code.
    ArmError,
    /// The arm reported a warning code.
    ArmWarning,
    EStop,
    DoorOpen,
    /// Ctrl-C or the operator's stop.
    OperatorStop,
    /// A joint outside its limits (with margin).
    JointLimit,
    /// A capture whose frame could not be queued for recording.
    CaptureNotRecorded,
    /// A frame the recorder could not write (malformed buffers).
    FrameMalformed,
    /// The recorder cannot write (disk full, file error).
    RecorderFailed,
    /// A controlled stop began.
    StopStarted,
    /// A controlled stop ended.
    StopDone,
    /// A device fault (camera, light, trigger).
    DeviceFault,
    /// Anything else; the detail says what.
    Other,
}

impl EventKind {
    /// The kebab-case name written to the file.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Deviation => "deviation",
            Self::ReportWatchdog => "report-watchdog",
            Self::ArmError => "arm-error",
            Self::ArmWarning => "arm-warning",
            Self::EStop => "e-stop",
            Self::DoorOpen => "door-open",
            Self::OperatorStop => "operator-stop",
            Self::JointLimit => "joint-limit",
            Self::CaptureNotRecorded => "capture-not-recorded",
            Self::FrameMalformed => "frame-malformed",
            Self::RecorderFailed => "recorder-failed",
            Self::StopStarted => "stop-started",
            Self::StopDone => "stop-done",
            Self::DeviceFault => "device-fault",
            Self::Other => "other",
        }
    }
}

/// The detail of a safety event: numbers from the tick (formatted by the recorder), or text
/// from code outside the tick.
#[derive(Debug, Clone, PartialEq)]
pub enum EventDetail {
    /// Raised by the tick: no allocation. `joint` is 1-based when the event concerns one joint.
    Numeric { tick: u64, joint: Option<u8>, value: f64, limit: f64 },
    /// Raised outside the tick.
    Text(String),
}

/// `/safety/event`: an interlock trip, fault or notable event.
#[derive(Debug, Clone, PartialEq)]
pub struct SafetyEventMsg {
    pub t_ns: u64,
    pub kind: EventKind,
    pub detail: EventDetail,
}

impl SafetyEventMsg {
    /// An event raised by the tick (never allocates).
    pub fn numeric(
        t_ns: u64,
        kind: EventKind,
        tick: u64,
        joint: Option<u8>,
        value: f64,
        limit: f64,
    ) -> Self {
        Self { t_ns, kind, detail: EventDetail::Numeric { tick, joint, value, limit } }
    }

    /// An event raised outside the tick, with a pre-formatted detail.
    pub fn text(t_ns: u64, kind: EventKind, detail: impl Into<String>) -> Self {
        Self { t_ns, kind, detail: EventDetail::Text(detail.into()) }
    }

    /// The human-readable detail as written to the file.
    pub fn detail_string(&self) -> String {
        match &self.detail {
            EventDetail::Text(s) => s.clone(),
            EventDetail::Numeric { tick, joint: Some(j), value, limit } => {
                format!("tick {tick} joint {j}: value {value} limit {limit}")
            }
            EventDetail::Numeric { tick, joint: None, value, limit } => {
                format!("tick {tick}: value {value} limit {limit}")
            }
        }
    }
}

/// `/tf`: the transforms between base, flange, camera and target at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TfMsg {
    pub t_ns: u64,
    /// `base_T_flange` (forward kinematics of the measured joints).
    pub base_flange: Pose,
    /// `flange_T_camera` (the camera mount, OpenCV camera axes).
    pub flange_camera: Pose,
    /// `base_T_target` (where the target sits in the arm-base frame).
    pub base_target: Pose,
}

impl TfMsg {
    /// `target_T_camera`: the camera's pose in the target frame.
    pub fn camera_in_target(&self) -> Pose {
        self.base_target.inverse() * self.base_flange * self.flange_camera
    }
}

/// Which of the closed loop's topics a [`ClosedLoopMsg`] goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClosedLoopTopic {
    /// `/closed_loop/filter`.
    Filter,
    /// `/closed_loop/correction`.
    Correction,
    /// `/closed_loop/gate`.
    Gate,
}

/// A `/closed_loop/*` message: JSON written by the navigator (`hitl run --closed-loop`,
/// docs/mcap-topics.md gives each topic's fields).
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoopMsg {
    pub topic: ClosedLoopTopic,
    pub t_ns: u64,
    pub value: serde_json::Value,
}

/// `/pose/gt` or `/pose/estimate`: the target's pose in the camera frame (OpenCV axes),
/// stamped with the capture time of the frame it belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseStamped {
    /// Capture time of the frame, host monotonic nanoseconds.
    pub capture_ns: u64,
    /// `camera_T_target`.
    pub pose: Pose,
}

/// One image plane, row-major, `channels` values per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Plane<T> {
    pub width: u32,
    pub height: u32,
    /// The camera frame's own buffer, shared with perception (not copied).
    pub data: SharedPixels<T>,
}

impl<T> Plane<T> {
    /// Whether the buffer holds exactly `width * height * channels` values.
    pub fn is_consistent(&self, channels: usize) -> bool {
        (self.width as usize)
            .checked_mul(self.height as usize)
            .and_then(|n| n.checked_mul(channels))
            == Some(self.data.len())
    }
}

/// A depth image as the camera delivered it.
#[derive(Debug, Clone, PartialEq)]
pub enum DepthImage {
    /// 32FC1, metres, 0 where there is no return.
    Metres(Plane<f32>),
    /// 16UC1, millimetres, 0 where there is no return (what the Orbbec delivers natively).
    Millimetres(Plane<u16>),
}

/// One capture as handed to the recorder by the camera intake (outside the tick).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRecord {
    /// The tick that fired the capture.
    pub tick: u64,
    /// Capture (exposure) time on the host monotonic clock, nanoseconds: every message of this
    /// frame (images, calibration, tf, ground-truth pose) is stamped with it.
    pub capture_ns: u64,
    pub intrinsics: Intrinsics,
    /// rgb8.
    pub color: Option<Plane<u8>>,
    pub depth: Option<DepthImage>,
    /// mono8, 255 target, 0 else.
    pub mask: Option<Plane<u8>>,
    /// Ground-truth `camera_T_target` (simulation, or a tracked target).
    pub gt_pose: Option<Pose>,
    /// The transforms at capture time.
    pub tf: Option<TfMsg>,
    /// When the tick fired the trigger (host monotonic ns): with `capture_ns` it gives the frame's
    /// `/camera/sync` record. `None` writes none.
    pub trigger_ns: Option<u64>,
    /// The light level in effect at the exposure, for `/camera/sync` (`None`: not known).
    pub light_level: Option<f32>,
}

impl FrameRecord {
    /// Take a camera frame (no pixel copies).
    pub fn from_rgbd(frame: RgbdFrame) -> Self {
        let i = frame.intrinsics;
        let CaptureRequest { tick, fired_ns } = frame.request;
        Self {
            tick,
            capture_ns: frame.exposure_ns,
            intrinsics: i,
            color: Some(Plane { width: i.width, height: i.height, data: frame.color }),
            depth: Some(DepthImage::Metres(Plane {
                width: i.width,
                height: i.height,
                data: frame.depth_m,
            })),
            mask: frame.mask.map(|m| Plane { width: i.width, height: i.height, data: m }),
            gt_pose: None,
            tf: None,
            trigger_ns: Some(fired_ns),
            light_level: None,
        }
    }
}

/// Convert metres to millimetres for 16UC1: rounded, 0 for no return, NaN, negative or
/// beyond 65.535 m.
pub fn metres_to_mm(m: f32) -> u16 {
    let mm = m * 1000.0;
    if mm.is_finite() && mm > 0.0 && mm <= 65535.0 {
        mm.round() as u16
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn trigger_fired_reads_recordings_without_the_host_time() {
        let old: TriggerFiredMsg =
            serde_json::from_str(r#"{"t_ns":9,"tick":3,"device_us":7}"#).expect("old message");
        assert_eq!((old.fired_ns, old.clock_error_ns), (None, None));
        let new = TriggerFiredMsg { fired_ns: Some(8), clock_error_ns: Some(2), ..old };
        let text = serde_json::to_string(&new).expect("json");
        assert!(text.contains(r#""fired_ns":8,"clock_error_ns":2"#), "{text}");
        assert_eq!(serde_json::from_str::<TriggerFiredMsg>(&text).expect("back"), new);
        assert!(!serde_json::to_string(&old).expect("json").contains("fired_ns"));
    }

    #[test]
    fn camera_in_target_frame() {
        // Flange 1 m in front of the target along base x, camera 0.1 m further along flange z
        // which points along base x (flange rotated +90 deg about base y).
        let h = std::f64::consts::FRAC_PI_2;
        let tf = TfMsg {
            t_ns: 0,
            base_flange: Pose::new(Vector3::new(1.0, 0.0, 0.5), Vector3::new(0.0, h, 0.0)),
            flange_camera: Pose::translation(0.0, 0.0, 0.1),
            base_target: Pose::translation(2.0, 0.0, 0.5),
        };
        let c = tf.camera_in_target().translation.vector;
        assert!((c[0] + 0.9).abs() < 1e-12 && c[1].abs() < 1e-12 && c[2].abs() < 1e-12, "{c:?}");
    }

    #[test]
    fn millimetres_clamp_bad_depth_to_no_return() {
        assert_eq!(metres_to_mm(1.2345), 1235);
        assert_eq!(metres_to_mm(0.0), 0);
        assert_eq!(metres_to_mm(-1.0), 0);
        assert_eq!(metres_to_mm(f32::NAN), 0);
        assert_eq!(metres_to_mm(70.0), 0);
    }
}
