//! Register (function) numbers of the xArm private protocol and the reply state bits.
//!
//! Numbers are those of the official SDK's configuration (`UxbusReg` in `x_config.py`). Only the
//! registers the controller, the official client's connect sequence and the stub use are named.

/// Firmware version string (40 bytes, NUL padded).
pub const GET_VERSION: u8 = 1;
/// Arm and control-box serial numbers (40 bytes: two NUL-terminated strings).
pub const GET_ROBOT_SN: u8 = 2;
/// Licence check (1 byte).
pub const CHECK_VERIFY: u8 = 3;
/// Whether the report carries torques (0) or currents (1).
pub const GET_REPORT_TAU_OR_I: u8 = 5;
/// Whether approximate motion is allowed (1 byte).
pub const GET_ALLOW_APPROX_MOTION: u8 = 7;
/// Enable or disable motors: params `[axis (8 = all), enable]`.
pub const MOTION_EN: u8 = 11;
/// Set the motion state: param `[state]` (0 ready/start, 3 pause, 4 stop).
pub const SET_STATE: u8 = 12;
/// Get the motion state (1 byte).
pub const GET_STATE: u8 = 13;
/// Number of cached commands (u16, big-endian).
pub const GET_CMDNUM: u8 = 14;
/// Controller error and warning codes (2 bytes).
pub const GET_ERROR: u8 = 15;
/// Clear the controller error.
pub const CLEAN_ERR: u8 = 16;
/// Clear the controller warning.
pub const CLEAN_WAR: u8 = 17;
/// Brake/joint power: params `[axis (1-7, 8 = all), 0 disable | 1 unlock]` (a system reset).
pub const SET_BRAKE: u8 = 18;
/// Set the mode: params `[mode]` or `[mode, detection_param]` (firmware >= 1.10).
pub const SET_MODE: u8 = 19;
/// Point-to-point joint move (mode 0): 7 joints, speed, acceleration, time (10 x f32).
pub const MOVE_JOINT: u8 = 23;
/// Servo joint setpoint (mode 1): 7 joints, speed, acceleration, time (10 x f32).
pub const MOVE_SERVOJ: u8 = 29;
/// TCP pose (6 x f32: mm and rad, roll-pitch-yaw).
pub const GET_TCP_POSE: u8 = 41;
/// Joint positions (7 x f32, rad).
pub const GET_JOINT_POS: u8 = 42;
/// Joint torques (7 x f32).
pub const GET_JOINT_TAU: u8 = 55;
/// Safety level (1 byte).
pub const GET_SAFE_LEVEL: u8 = 57;
/// Hardware types (2 bytes).
pub const GET_HD_TYPES: u8 = 141;
/// Motion-feedback packets the box pushes on the command socket (register byte 0xFF).
pub const FEEDBACK: u8 = 0xFF;

/// Reply state bit: the controller has an uncleared error.
pub const STATE_ERROR: u8 = 0x40;
/// Reply state bit: the controller has an uncleared warning.
pub const STATE_WARNING: u8 = 0x20;
/// Reply state bit: the arm is not ready to move (motors off, stopped, or in error).
pub const STATE_NOT_READY: u8 = 0x10;
/// Reply state bit: the request was invalid or failed.
pub const STATE_INVALID: u8 = 0x08;

/// Arm states as the box reports them.
pub mod arm_state {
    /// Moving.
    pub const MOVING: u8 = 1;
    /// Ready, not moving ("sleeping").
    pub const SLEEPING: u8 = 2;
    /// Paused.
    pub const PAUSED: u8 = 3;
    /// Stopped (after a stop request, an error, or before the first `set_state(0)`).
    pub const STOPPED: u8 = 4;
    /// Set-state value that starts (readies) the arm.
    pub const START: u8 = 0;
}

/// Arm modes.
pub mod mode {
    /// Position mode (planned moves).
    pub const POSITION: u8 = 0;
    /// Servo mode: the latest servo_j is executed at once.
    pub const SERVO: u8 = 1;
}

/// A short name for a register, for logs and errors.
pub fn name(register: u8) -> &'static str {
    match register {
        GET_VERSION => "get_version",
        GET_ROBOT_SN => "get_robot_sn",
        CHECK_VERIFY => "check_verify",
        GET_REPORT_TAU_OR_I => "get_report_tau_or_i",
        GET_ALLOW_APPROX_MOTION => "get_allow_approx_motion",
        MOTION_EN => "motion_enable",
        SET_STATE => "set_state",
        GET_STATE => "get_state",
        GET_CMDNUM => "get_cmdnum",
        GET_ERROR => "get_error",
        CLEAN_ERR => "clean_error",
        CLEAN_WAR => "clean_warn",
        SET_BRAKE => "set_brake",
        SET_MODE => "set_mode",
        MOVE_JOINT => "move_joint",
        MOVE_SERVOJ => "servo_j",
        GET_TCP_POSE => "get_tcp_pose",
        GET_JOINT_POS => "get_joint_pos",
        GET_JOINT_TAU => "get_joint_tau",
        GET_SAFE_LEVEL => "get_safe_level",
        GET_HD_TYPES => "get_hd_types",
        FEEDBACK => "feedback",
        _ => "register",
    }
}
