//! Controller error and warning codes, with the meanings the official SDK gives them.
//!
//! The box reports one error code and one warning code (u8 each). The stub raises the codes named
//! here as constants; [`error_name`] and [`warning_name`] give the meaning of any known code.

/// The control box's emergency-stop button is pressed.
pub const ERR_ESTOP_BUTTON: u8 = 1;
/// The control box's emergency-stop input (the enclosure's e-stop chain) is open.
pub const ERR_ESTOP_IO: u8 = 2;
/// A servo motor reported a fault (10 generic, 11-17 joints 1-7).
pub const ERR_SERVO: u8 = 10;
/// Self-collision detected by the controller's model.
pub const ERR_SELF_COLLISION: u8 = 22;
/// A joint angle is (or would be) beyond its limit.
pub const ERR_JOINT_LIMIT: u8 = 23;
/// Speed beyond the limit.
pub const ERR_SPEED_LIMIT: u8 = 24;
/// Joint speed measured by the servos beyond the limit.
pub const ERR_FEEDBACK_SPEED: u8 = 30;
/// A collision caused abnormal motor current (contact with the scene).
pub const ERR_COLLISION: u8 = 31;
/// Safety boundary (reduced mode fence) reached.
pub const ERR_SAFETY_BOUNDARY: u8 = 35;
/// Linear speed beyond the limit in servo_j mode.
pub const ERR_SERVOJ_LINEAR_SPEED: u8 = 60;

/// The controller's command cache is full.
pub const WARN_CACHE_FULL: u8 = 11;
/// A command parameter was out of range.
pub const WARN_PARAM: u8 = 12;
/// The command (register) does not exist.
pub const WARN_NO_SUCH_COMMAND: u8 = 13;
/// The command has no solution.
pub const WARN_NO_SOLUTION: u8 = 14;

/// What a controller error code means (`None` for codes the SDK does not name).
pub fn error_name(code: u8) -> Option<&'static str> {
    Some(match code {
        0 => "no error",
        1 => "emergency stop button on the control box pressed",
        2 => "emergency IO of the control box triggered",
        3 => "emergency stop of the three-state switch pressed",
        10 => "servo motor error",
        11..=17 => "servo motor error (joint 1-7: code minus 10)",
        18 => "force-torque sensor communication error",
        19 => "end effector communication error",
        21 => "kinematic error",
        22 => "self-collision error",
        23 => "joint angle exceeds limit",
        24 => "speed exceeds limit",
        25 => "planning error",
        26 => "Linux RT error",
        27 => "command reply error",
        28 => "end module communication error",
        30 => "feedback speed exceeds limit",
        31 => "collision caused abnormal current",
        32 => "three-point circle calculation error",
        33 => "controller GPIO error",
        34 => "recording timeout",
        35 => "safety boundary limit",
        36 => "too many delayed commands",
        37 => "abnormal movement in manual mode",
        38 => "abnormal joint angle",
        39 => "power board master/slave communication error",
        40 => "error-free joint trajectory solution failure",
        41 => "invalid friction file",
        42 => "invalid calibration file",
        50 => "six-axis force-torque sensor read error",
        51 => "six-axis force-torque sensor set-mode error",
        52 => "six-axis force-torque sensor set-zero error",
        53 => "six-axis force-torque sensor overloaded",
        60 => "linear speed exceeded limit in servo_j mode",
        110 => "arm base board communication error",
        111 => "control box external RS-485 device communication error",
        _ => return None,
    })
}

/// What a controller warning code means (`None` for codes the SDK does not name).
pub fn warning_name(code: u8) -> Option<&'static str> {
    Some(match code {
        0 => "no warning",
        11 => "controller command cache full",
        12 => "command parameter error",
        13 => "command does not exist",
        14 => "command has no solution",
        15 => "modbus command cache full",
        _ => return None,
    })
}

/// Whether the box stops the arm for this error (every non-zero controller error does).
pub fn error_stops_motion(code: u8) -> bool {
    code != 0
}
