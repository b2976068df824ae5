//! Interlocks: the conditions that end a run, what each one allows, and its exit code.
//!
//! The tick evaluates [`Interlocks::check`] once per period on plain values it already has (no
//! I/O, no allocation). The first trip wins; later ones are not recorded over it.

use crate::exit;
use crate::telemetry::{Device, TripKind};
use hitl_hal::{ArmState, InputState, Joints, DOF};

/// What the loop may still do after a trip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Motion is still possible and safe to command: a jerk-limited Ruckig stop.
    ControlledStop,
    /// Commanding motion is impossible or forbidden: tell the arm to stop (if it can still hear)
    /// and hold.
    Hold,
}

impl TripKind {
    /// A short stable name for `/safety/event` records and messages.
    pub fn name(&self) -> &'static str {
        match self {
            TripKind::ReportWatchdog { .. } => "report-watchdog",
            TripKind::ConnectionLost => "connection-lost",
            TripKind::SetpointsUnanswered => "setpoints-unanswered",
            TripKind::ArmError { .. } => "arm-error",
            TripKind::ArmWarning { .. } => "arm-warning",
            TripKind::Deviation { .. } => "deviation",
            TripKind::EStop => "estop",
            TripKind::DoorOpen => "door-open",
            TripKind::OperatorStop => "operator-stop",
            TripKind::RecorderFailed => "recorder-failed",
            TripKind::DeviceFailed { .. } => "device-failed",
        }
    }

    /// What the loop may still do.
    pub fn reaction(&self) -> Reaction {
        match self {
            // The arm cannot hear us (or does not answer what it hears), has stopped itself on an
            // error, or its power is cut.
            TripKind::ConnectionLost
            | TripKind::SetpointsUnanswered
            | TripKind::ArmError { .. }
            | TripKind::EStop => Reaction::Hold,
            _ => Reaction::ControlledStop,
        }
    }

    /// The contract's exit code for a run ended by this trip.
    pub fn exit_code(&self) -> u8 {
        match self {
            TripKind::OperatorStop => exit::OPERATOR_STOP,
            TripKind::ConnectionLost
            | TripKind::SetpointsUnanswered
            | TripKind::DeviceFailed { .. } => exit::DEVICE,
            _ => exit::INTERLOCK,
        }
    }

    /// A human sentence (formatted outside the tick).
    pub fn detail(&self) -> String {
        match self {
            TripKind::ReportWatchdog { silent_ms } => {
                format!("no arm report for {silent_ms:.1} ms")
            }
            TripKind::ConnectionLost => "the command connection to the arm failed".into(),
            TripKind::SetpointsUnanswered => {
                "the arm stopped answering setpoints for longer than interlocks.reply_stall_ms"
                    .into()
            }
            // Code 0: the reply to a setpoint flagged an error (or "not ready") before any report
            // carried the code (the 5 Hz report that does may come 200 ms later).
            TripKind::ArmError { code: 0 } => {
                "the arm refused a setpoint: its reply flagged an error or not-ready state before \
                 a report carried the error code"
                    .into()
            }
            TripKind::ArmError { code } => format!("the arm reports error code {code}"),
            TripKind::ArmWarning { code } => format!("the arm reports warning code {code}"),
            TripKind::Deviation { joint, deviation_rad } => format!(
                "joint {} is {:.4} rad ({:.2} deg) from its command",
                joint + 1,
                deviation_rad,
                deviation_rad.to_degrees()
            ),
            TripKind::EStop => "the e-stop is pressed".into(),
            TripKind::DoorOpen => "the enclosure door is open".into(),
            TripKind::OperatorStop => "the operator stopped the run (Ctrl-C)".into(),
            TripKind::RecorderFailed => "the recorder cannot write; the run is not recorded".into(),
            TripKind::DeviceFailed { device } => format!("the {} failed", device.as_str()),
        }
    }
}

/// Thresholds, from the lab configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    pub report_timeout_ns: u64,
    pub max_deviation_rad: f64,
    pub trip_on_warning: bool,
    /// How long the command channel may leave setpoints unanswered.
    pub reply_stall_ns: u64,
}

impl Thresholds {
    pub fn from_lab(lab: &hitl_trajectories::lab::LabConfig) -> Self {
        Self {
            report_timeout_ns: lab.interlocks.report_timeout_ms.saturating_mul(1_000_000),
            max_deviation_rad: lab.interlocks.max_deviation_rad,
            trip_on_warning: lab.interlocks.trip_on_warning,
            reply_stall_ns: lab.interlocks.reply_stall_ms.saturating_mul(1_000_000),
        }
    }

    /// How many setpoint replies may be missing before the arm counts as silent: as many as the
    /// loop sends in `reply_stall` at `rate_hz` (63 at the defaults, 250 ms and 250 Hz). A
    /// shorter stall is ridden through: the reports and the deviation interlock still watch the
    /// arm every tick (docs/safety.md, "Reply stalls").
    pub fn unanswered_setpoints(&self, rate_hz: f64) -> u32 {
        let ticks = (self.reply_stall_ns as f64 * 1e-9 * rate_hz).ceil();
        if ticks.is_finite() {
            ticks.clamp(1.0, f64::from(u32::MAX)) as u32
        } else {
            1
        }
    }
}

/// Everything the interlocks look at in one tick.
#[derive(Debug, Clone, Copy)]
pub struct Sense<'a> {
    pub now_ns: u64,
    pub arm: Option<&'a ArmState>,
    /// The setpoint the arm should be near (the last one sent).
    pub commanded: &'a Joints,
    pub inputs: InputState,
    pub operator_stop: bool,
    pub recorder_failed: bool,
    pub device_failed: Option<Device>,
    /// Whether deviation is checked this tick (not while the stream has just started).
    pub check_deviation: bool,
}

/// The interlock set of a run.
#[derive(Debug, Clone, Copy)]
pub struct Interlocks {
    pub thresholds: Thresholds,
}

impl Interlocks {
    pub fn new(thresholds: Thresholds) -> Self {
        Self { thresholds }
    }

    /// The first condition that trips, in order of severity.
    pub fn check(&self, s: &Sense<'_>) -> Option<TripKind> {
        if s.inputs.estop_pressed {
            return Some(TripKind::EStop);
        }
        if s.operator_stop {
            return Some(TripKind::OperatorStop);
        }
        let Some(arm) = s.arm else {
            return Some(TripKind::ReportWatchdog { silent_ms: f64::INFINITY });
        };
        if arm.error_code != 0 {
            return Some(TripKind::ArmError { code: arm.error_code });
        }
        let silent = s.now_ns.saturating_sub(arm.received_ns);
        if silent > self.thresholds.report_timeout_ns {
            return Some(TripKind::ReportWatchdog { silent_ms: silent as f64 / 1e6 });
        }
        if self.thresholds.trip_on_warning && arm.warn_code != 0 {
            return Some(TripKind::ArmWarning { code: arm.warn_code });
        }
        if s.inputs.door_open {
            return Some(TripKind::DoorOpen);
        }
        if s.check_deviation {
            for j in 0..DOF {
                let d = (arm.q[j] - s.commanded[j]).abs();
                // NaN from the arm counts as a deviation too.
                if d.is_nan() || d > self.thresholds.max_deviation_rad {
                    return Some(TripKind::Deviation { joint: j, deviation_rad: d });
                }
            }
        }
        if s.recorder_failed {
            return Some(TripKind::RecorderFailed);
        }
        if let Some(device) = s.device_failed {
            return Some(TripKind::DeviceFailed { device });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sense<'a>(arm: Option<&'a ArmState>, cmd: &'a Joints) -> Sense<'a> {
        Sense {
            now_ns: 1_000_000_000,
            arm,
            commanded: cmd,
            inputs: InputState::default(),
            operator_stop: false,
            recorder_failed: false,
            device_failed: None,
            check_deviation: true,
        }
    }

    fn il() -> Interlocks {
        Interlocks::new(Thresholds {
            report_timeout_ns: 100_000_000,
            max_deviation_rad: 0.08,
            trip_on_warning: true,
            reply_stall_ns: 250_000_000,
        })
    }

    #[test]
    fn the_command_channel_may_stall_for_the_labs_reply_stall() {
        let lab = Thresholds::from_lab(&hitl_trajectories::lab::LabConfig::default());
        assert_eq!(lab, il().thresholds);
        // 250 ms: a 190 ms stall (47.5 setpoints at 250 Hz) is ridden through.
        assert_eq!(il().thresholds.unanswered_setpoints(250.0), 63);
        assert!(f64::from(il().thresholds.unanswered_setpoints(250.0)) > 0.19 * 250.0);
        assert_eq!(il().thresholds.unanswered_setpoints(100.0), 25);
        let shared_vm = Thresholds { reply_stall_ns: 1_000_000_000, ..il().thresholds };
        assert_eq!(shared_vm.unanswered_setpoints(250.0), 250);
        let zero = Thresholds { reply_stall_ns: 0, ..il().thresholds };
        assert_eq!(zero.unanswered_setpoints(250.0), 1, "at least one reply may be in flight");
        assert_eq!(il().thresholds.unanswered_setpoints(f64::NAN), 1);
    }

    #[test]
    fn a_fresh_matching_report_trips_nothing() {
        let arm = ArmState { received_ns: 990_000_000, ..Default::default() };
        assert_eq!(il().check(&sense(Some(&arm), &[0.0; DOF])), None);
    }

    #[test]
    fn each_condition_trips_with_its_kind_reaction_and_exit_code() {
        let cmd = [0.0; DOF];
        let fresh = ArmState { received_ns: 990_000_000, ..Default::default() };
        let stale = ArmState { received_ns: 800_000_000, ..Default::default() };
        let t = il().check(&sense(Some(&stale), &cmd)).expect("watchdog");
        assert!(
            matches!(t, TripKind::ReportWatchdog { silent_ms } if (silent_ms - 200.0).abs() < 1e-9)
        );
        assert_eq!((t.reaction(), t.exit_code()), (Reaction::ControlledStop, 4));

        let err = ArmState { error_code: 23, ..fresh };
        let t = il().check(&sense(Some(&err), &cmd)).expect("error");
        assert_eq!(t, TripKind::ArmError { code: 23 });
        assert_eq!((t.reaction(), t.exit_code()), (Reaction::Hold, 4));
        assert_eq!(t.detail(), "the arm reports error code 23");
        let refused = TripKind::ArmError { code: 0 }.detail();
        assert!(refused.contains("refused a setpoint") && !refused.contains("code 0"), "{refused}");

        let mut off = fresh;
        off.q[4] = 0.1;
        let t = il().check(&sense(Some(&off), &cmd)).expect("deviation");
        assert!(matches!(t, TripKind::Deviation { joint: 4, .. }));

        let mut s = sense(Some(&fresh), &cmd);
        s.inputs.door_open = true;
        assert_eq!(il().check(&s), Some(TripKind::DoorOpen));
        s.inputs.estop_pressed = true;
        assert_eq!(il().check(&s), Some(TripKind::EStop), "e-stop outranks the door");

        let mut s = sense(Some(&fresh), &cmd);
        s.operator_stop = true;
        assert_eq!(il().check(&s).map(|t| t.exit_code()), Some(130));
        let mut s = sense(Some(&fresh), &cmd);
        s.device_failed = Some(Device::Camera);
        assert_eq!(il().check(&s).map(|t| t.exit_code()), Some(5));
        let mut s = sense(Some(&fresh), &cmd);
        s.recorder_failed = true;
        assert_eq!(il().check(&s), Some(TripKind::RecorderFailed));
    }

    #[test]
    fn nan_from_the_arm_is_a_deviation() {
        let mut arm = ArmState { received_ns: 990_000_000, ..Default::default() };
        arm.q[0] = f64::NAN;
        assert!(matches!(
            il().check(&sense(Some(&arm), &[0.0; DOF])),
            Some(TripKind::Deviation { joint: 0, .. })
        ));
    }
}
