//! Fault injection for the stub: what can go wrong, when, and the simulated safety inputs.
//!
//! A fault is written `KIND[:VALUE]@SECONDS` (the form `hitl run --stub-fault` takes), seconds
//! counted from the stub's start:
//!
//! | kind | value | effect |
//! | --- | --- | --- |
//! | `drop-connection` | - | close every client connection (command and reports); new ones are accepted |
//! | `stall-reports` | seconds (default: for good) | report ports stop sending, sockets stay open |
//! | `stall-replies` | seconds (default: for good) | the command port reads and answers nothing, the connection stays open |
//! | `arm-error` | controller error code (default 10, servo motor error) | the box raises the error and stops |
//! | `deviation` | radians (default 0.15) | added to every reported joint (reports and get_joint_pos) |
//! | `estop` | - | the e-stop input reads pressed; the box raises error 2 (emergency IO) and stops |
//! | `door-open` | - | the door input reads open (the box itself does not see the door) |
//!
//! Every default trips the interlock it is named after under the default lab: the stalls last
//! longer than any silence limit, the deviation is almost twice the lab's 0.08 rad limit.

use hitl_hal::{ErrorKind, ErrorType, InputState, Inputs};
use std::fmt;
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};

/// What a fault does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    DropConnection,
    /// Stop the reports for this many seconds (`None`: until the stub stops).
    StallReports(Option<f64>),
    /// Stop reading and answering commands for this many seconds (`None`: until the stub
    /// stops); the connection and the reports go on.
    StallReplies(Option<f64>),
    /// Raise this controller error code.
    ArmError(u8),
    /// Add this offset (rad) to every reported joint.
    Deviation(f64),
    Estop,
    DoorOpen,
}

/// Default code of an injected arm error: servo motor error.
pub const DEFAULT_ARM_ERROR: u8 = 10;
/// Default injected deviation, radians: well beyond the default lab's 0.08 rad deviation limit
/// (`interlocks.max_deviation_rad`), so the fault trips what it is named after.
pub const DEFAULT_DEVIATION_RAD: f64 = 0.15;

impl FaultKind {
    pub fn name(&self) -> &'static str {
        match self {
            FaultKind::DropConnection => "drop-connection",
            FaultKind::StallReports(_) => "stall-reports",
            FaultKind::StallReplies(_) => "stall-replies",
            FaultKind::ArmError(_) => "arm-error",
            FaultKind::Deviation(_) => "deviation",
            FaultKind::Estop => "estop",
            FaultKind::DoorOpen => "door-open",
        }
    }
}

/// A fault and when it strikes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    pub kind: FaultKind,
    /// Seconds after the stub started.
    pub at_s: f64,
}

/// Why a fault specification was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("bad stub fault '{spec}': {reason} (expected KIND[:VALUE]@SECONDS with KIND one of drop-connection, stall-reports, stall-replies, arm-error, deviation, estop, door-open)")]
pub struct FaultParseError {
    pub spec: String,
    pub reason: String,
}

impl FromStr for Fault {
    type Err = FaultParseError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let err = |reason: &str| FaultParseError { spec: spec.to_string(), reason: reason.into() };
        let (head, at) = spec.trim().rsplit_once('@').ok_or_else(|| err("missing '@SECONDS'"))?;
        let at_s: f64 = at.trim().parse().map_err(|_| err("time is not a number"))?;
        if !at_s.is_finite() || at_s < 0.0 {
            return Err(err("time must be a finite number of seconds >= 0"));
        }
        let (name, value) = match head.split_once(':') {
            Some((n, v)) => (n.trim(), Some(v.trim())),
            None => (head.trim(), None),
        };
        let number = |v: &str| -> Result<f64, FaultParseError> {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err("value is not a finite number"))
        };
        let stall = |v: &str| -> Result<f64, FaultParseError> {
            let s = number(v)?;
            if s <= 0.0 {
                return Err(err("stall duration must be > 0"));
            }
            Ok(s)
        };
        let kind = match (name, value) {
            ("drop-connection", None) => FaultKind::DropConnection,
            ("stall-reports", None) => FaultKind::StallReports(None),
            ("stall-reports", Some(v)) => FaultKind::StallReports(Some(stall(v)?)),
            ("stall-replies", None) => FaultKind::StallReplies(None),
            ("stall-replies", Some(v)) => FaultKind::StallReplies(Some(stall(v)?)),
            ("arm-error", None) => FaultKind::ArmError(DEFAULT_ARM_ERROR),
            ("arm-error", Some(v)) => match v.parse::<u8>() {
                Ok(c) if c > 0 => FaultKind::ArmError(c),
                _ => return Err(err("arm error code must be 1-255")),
            },
            ("deviation", None) => FaultKind::Deviation(DEFAULT_DEVIATION_RAD),
            ("deviation", Some(v)) => FaultKind::Deviation(number(v)?),
            ("estop", None) => FaultKind::Estop,
            ("door-open", None) => FaultKind::DoorOpen,
            ("drop-connection" | "estop" | "door-open", Some(_)) => {
                return Err(err("this kind takes no value"))
            }
            _ => return Err(err("unknown kind")),
        };
        Ok(Fault { kind, at_s })
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            FaultKind::StallReports(Some(s)) => write!(f, "stall-reports:{s}@{}", self.at_s),
            FaultKind::StallReplies(Some(s)) => write!(f, "stall-replies:{s}@{}", self.at_s),
            FaultKind::ArmError(c) => write!(f, "arm-error:{c}@{}", self.at_s),
            FaultKind::Deviation(d) => write!(f, "deviation:{d}@{}", self.at_s),
            k => write!(f, "{}@{}", k.name(), self.at_s),
        }
    }
}

/// Faults not yet struck, earliest first.
#[derive(Debug, Clone, Default)]
pub struct FaultSchedule {
    pending: Vec<Fault>,
}

impl FaultSchedule {
    pub fn new(mut faults: Vec<Fault>) -> Self {
        faults.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
        Self { pending: faults }
    }

    /// Take the next fault due at time `t_s`, if any.
    pub fn next_due(&mut self, t_s: f64) -> Option<Fault> {
        match self.pending.first() {
            Some(f) if f.at_s <= t_s => Some(self.pending.remove(0)),
            _ => None,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }
}

/// The enclosure's safety inputs as the stub simulates them (shared with the controller).
#[derive(Debug, Default)]
pub struct SimInputs {
    estop: AtomicBool,
    door_open: AtomicBool,
}

impl SimInputs {
    pub fn set_estop(&self, pressed: bool) {
        self.estop.store(pressed, Ordering::SeqCst);
    }
    pub fn set_door_open(&self, open: bool) {
        self.door_open.store(open, Ordering::SeqCst);
    }
    pub fn state(&self) -> InputState {
        InputState {
            estop_pressed: self.estop.load(Ordering::SeqCst),
            door_open: self.door_open.load(Ordering::SeqCst),
        }
    }
}

/// A reader of the simulated inputs for the controller (cheap to clone, never blocks).
#[derive(Debug, Clone, Default)]
pub struct SimInputsReader(pub std::sync::Arc<SimInputs>);

impl ErrorType for SimInputsReader {
    type Error = ErrorKind;
}

impl Inputs for SimInputsReader {
    fn read(&mut self) -> Result<InputState, ErrorKind> {
        Ok(self.0.state())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_kind() {
        let f: Fault = "deviation:0.1@2.5".parse().expect("valid");
        assert_eq!(f, Fault { kind: FaultKind::Deviation(0.1), at_s: 2.5 });
        assert_eq!("estop@1".parse::<Fault>().map(|f| f.kind), Ok(FaultKind::Estop));
        assert_eq!("arm-error@0".parse::<Fault>().map(|f| f.kind), Ok(FaultKind::ArmError(10)));
        assert_eq!("arm-error:31@0".parse::<Fault>().map(|f| f.kind), Ok(FaultKind::ArmError(31)));
        assert_eq!(
            "stall-reports:0.5@3".parse::<Fault>().map(|f| f.kind),
            Ok(FaultKind::StallReports(Some(0.5)))
        );
        assert_eq!(
            "stall-replies@3".parse::<Fault>().map(|f| f.kind),
            Ok(FaultKind::StallReplies(None))
        );
        assert_eq!(
            "stall-replies:2@3".parse::<Fault>().map(|f| f.kind),
            Ok(FaultKind::StallReplies(Some(2.0)))
        );
        assert_eq!("door-open@4".parse::<Fault>().map(|f| f.kind), Ok(FaultKind::DoorOpen));
        assert_eq!(
            "drop-connection@4".parse::<Fault>().map(|f| f.kind),
            Ok(FaultKind::DropConnection)
        );
        for f in [
            "deviation:0.1@2.5",
            "estop@1",
            "stall-reports:0.5@3",
            "stall-replies:0.5@3",
            "arm-error:31@0",
        ] {
            let parsed: Fault = f.parse().expect("valid");
            assert_eq!(parsed.to_string().parse::<Fault>(), Ok(parsed));
        }
    }

    #[test]
    fn the_default_deviation_exceeds_the_default_lab_limit_with_margin() {
        let limit = hitl_trajectories::lab::LabConfig::default().interlocks.max_deviation_rad;
        assert!(DEFAULT_DEVIATION_RAD >= 1.5 * limit, "{DEFAULT_DEVIATION_RAD} vs {limit}");
        assert_eq!(
            "deviation@1".parse::<Fault>().map(|f| f.kind),
            Ok(FaultKind::Deviation(DEFAULT_DEVIATION_RAD))
        );
    }

    #[test]
    fn refuses_bad_specs_with_a_reason() {
        for bad in [
            "estop",
            "estop@-1",
            "estop@x",
            "meteor@1",
            "arm-error:0@1",
            "estop:1@1",
            "deviation:nan@1",
            "stall-replies:0@1",
        ] {
            let e = bad.parse::<Fault>().expect_err(bad);
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    #[test]
    fn schedule_releases_in_time_order() {
        let mut s = FaultSchedule::new(vec![
            "estop@2".parse().expect("valid"),
            "door-open@1".parse().expect("valid"),
        ]);
        assert_eq!(s.next_due(0.5), None);
        assert_eq!(s.next_due(1.5).map(|f| f.kind), Some(FaultKind::DoorOpen));
        assert_eq!(s.next_due(1.5), None);
        assert_eq!(s.next_due(2.0).map(|f| f.kind), Some(FaultKind::Estop));
        assert!(s.is_empty());
    }
}
