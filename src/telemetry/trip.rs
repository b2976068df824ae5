//! A trip as a fact: which interlock fired, on which tick, at what time. The interlocks decide
//! trips and what they mean; the recorder and the operator's messages read them.

/// What tripped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TripKind {
    /// No arm report for longer than the watchdog allows.
    ReportWatchdog { silent_ms: f64 },
    /// The command connection to the arm failed (closed, reset, unreadable bytes).
    ConnectionLost,
    /// The connection is open but the arm stopped answering setpoints (or accepting them) for
    /// longer than the reply stall the lab rides through (`interlocks.reply_stall_ms`).
    SetpointsUnanswered,
    /// The arm reports an error code.
    ArmError { code: u8 },
    /// The arm reports a warning code.
    ArmWarning { code: u8 },
    /// Commanded and measured joints differ by more than allowed.
    Deviation { joint: usize, deviation_rad: f64 },
    /// The e-stop input is pressed.
    EStop,
    /// The enclosure door is open.
    DoorOpen,
    /// The operator asked to stop (Ctrl-C).
    OperatorStop,
    /// The recorder cannot write (disk full, file error).
    RecorderFailed,
    /// A device the run needs failed (camera, light, trigger, inputs).
    DeviceFailed { device: Device },
}

/// Devices other than the arm whose failure ends the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Device {
    Camera,
    Light,
    Trigger,
    Inputs,
}

impl Device {
    pub fn as_str(self) -> &'static str {
        match self {
            Device::Camera => "camera",
            Device::Light => "light",
            Device::Trigger => "trigger",
            Device::Inputs => "inputs",
        }
    }
}

/// A trip: what and when (tick).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trip {
    pub kind: TripKind,
    pub tick: u64,
    pub t_ns: u64,
}
