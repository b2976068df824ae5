//! The control box's state machine over a [`Plant`]: identity (serial number, firmware),
//! motors, states, modes, the "system reset" registers, error and warning codes, servo and joint
//! moves, the firmware's joint-limit, speed and collision errors, and the replies it gives.
//!
//! Pure logic: no sockets, no threads. The command server calls [`ArmBox::handle`] for every
//! request (with the time it handles it); the stepping thread calls [`ArmBox::step`] every
//! physics step. Every rule and its source is in `docs/xarm-protocol.md`.

use crate::plant::{Collision, Plant};
use hitl_drivers::xarm::codes;
use hitl_drivers::xarm::registers::{self as reg, arm_state, mode};
use hitl_drivers::xarm::report::{BoxIdentity, ReportData};
use hitl_hal::{Joints, DOF};
use nalgebra::Vector3;

/// Arm serial number the stub answers unless told otherwise: a current xArm7 (digits [2:6] in
/// 1305..=8499, so the official SDK and the controller pick the current joint-limit table).
pub const DEFAULT_ARM_SN: &str = "XS1305HITL01";
/// Control-box serial number (digits [2:6] >= 1300: the SDK's "1300" control box).
pub const DEFAULT_BOX_SN: &str = "XX1305HITL01";
/// Firmware version the stub answers unless told otherwise (>= 1.10 so the SDK sends two-byte
/// set_mode, >= 1.8.6 so it switches to protocol id 3, >= 2.3.0 so error 60 applies).
pub const DEFAULT_FIRMWARE: &str = "v2.5.0";
/// Longest serial number accepted (get_robot_sn's field is 40 bytes for both, NUL separated).
pub const MAX_SN_LEN: usize = 16;
/// Longest get_version text: its field is 40 bytes and the SDK reads it up to a NUL.
pub const MAX_VERSION_TEXT: usize = 39;

/// The firmware's joint speed limit, 180 deg/s (rad/s): servo_j targets that ask for more raise
/// error 24, measured joint speeds above it error 30.
pub const MAX_JOINT_SPEED: f64 = std::f64::consts::PI;
/// TCP linear speed limit in servo_j (firmware >= 2.3.0): 1.2 x 1000 mm/s, m/s (error 60).
pub const MAX_SERVO_J_TCP_SPEED: f64 = 1.2;
/// The box's control period: the shortest time a servo_j step is taken over, s.
pub const BOX_PERIOD_S: f64 = 0.004;
/// The longest time a servo_j step is taken over (a first setpoint, or one after a pause), s.
pub const MAX_STEP_INTERVAL_S: f64 = 0.05;
/// Joint speed above which the arm reports itself moving (state 1), rad/s.
const MOVING_SPEED: f64 = 0.005;
/// Largest reply data the box produces (get_joint_pos with positions, velocities, efforts).
pub const MAX_REPLY_DATA: usize = 96;

/// A reply: state byte and data.
#[derive(Debug, Clone, Copy)]
pub struct BoxReply {
    pub state: u8,
    pub len: usize,
    pub data: [u8; MAX_REPLY_DATA],
}

impl BoxReply {
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len]
    }
}

/// Who the box says it is: serial numbers and firmware version.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BoxIdentityConfig {
    pub arm_sn: String,
    pub box_sn: String,
    /// `vMAJOR.MINOR.PATCH`.
    pub firmware: String,
}

impl Default for BoxIdentityConfig {
    fn default() -> Self {
        Self {
            arm_sn: DEFAULT_ARM_SN.into(),
            box_sn: DEFAULT_BOX_SN.into(),
            firmware: DEFAULT_FIRMWARE.into(),
        }
    }
}

/// Why an identity was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IdentityError {
    #[error("serial number {0:?}: expected 1-16 ASCII letters and digits")]
    Serial(String),
    #[error("firmware version {0:?}: expected vMAJOR.MINOR.PATCH (numbers)")]
    Firmware(String),
    #[error("version text {0:?} is longer than the box's {MAX_VERSION_TEXT} bytes: shorten the serial numbers")]
    TooLong(String),
}

impl BoxIdentityConfig {
    /// The firmware version as numbers, if well formed.
    pub fn firmware_number(&self) -> Option<(u32, u32, u32)> {
        parse_firmware(&self.firmware)
    }

    /// Refuse what a box could not say (the version text must fit its 40-byte field).
    pub fn validate(&self) -> Result<(), IdentityError> {
        for sn in [&self.arm_sn, &self.box_sn] {
            let ok = !sn.is_empty()
                && sn.len() <= MAX_SN_LEN
                && sn.bytes().all(|b| b.is_ascii_alphanumeric());
            if !ok {
                return Err(IdentityError::Serial(sn.clone()));
            }
        }
        if parse_firmware(&self.firmware).is_none() {
            return Err(IdentityError::Firmware(self.firmware.clone()));
        }
        let text = self.version_text();
        if text.len() > MAX_VERSION_TEXT {
            return Err(IdentityError::TooLong(text));
        }
        Ok(())
    }

    /// The get_version text: `axis,type,arm_sn,box_sn,firmware` (xArm7, type 7).
    fn version_text(&self) -> String {
        format!("7,7,{},{},{}", self.arm_sn, self.box_sn, self.firmware)
    }
}

/// `vX.Y.Z` as numbers.
pub fn parse_firmware(v: &str) -> Option<(u32, u32, u32)> {
    let mut it = v.strip_prefix('v')?.split('.').map(|p| {
        if !p.is_empty() && p.len() <= 4 && p.bytes().all(|b| b.is_ascii_digit()) {
            p.parse::<u32>().ok()
        } else {
            None
        }
    });
    let (a, b, c) = (it.next()??, it.next()??, it.next()??);
    it.next().is_none().then_some((a, b, c))
}

/// What the box is doing, for handles and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoxStatus {
    pub enabled: bool,
    pub state: u8,
    pub mode: u8,
    pub error_code: u8,
    pub warn_code: u8,
}

/// The box: state machine plus the plant it drives.
pub struct ArmBox {
    plant: Box<dyn Plant>,
    limits: [(f64, f64); DOF],
    identity: BoxIdentityConfig,
    /// get_version's 40-byte answer.
    version_text: String,
    /// Error 60 exists from firmware 2.3.0 on.
    checks_tcp_speed: bool,
    enabled: bool,
    state: u8,
    mode: u8,
    error: u8,
    warn: u8,
    /// The position target last given to the plant.
    target: Joints,
    /// A planned joint move in mode 0: goal and joint speed (rad/s).
    moving_to: Option<(Joints, f64)>,
    /// When the last servo_j target was taken (or the arm was readied), seconds on the clock
    /// `handle` is given.
    last_servo_s: Option<f64>,
    /// Offset added to reported joints (deviation fault).
    deviation: f64,
    /// The e-stop input is pressed: error 2 cannot be cleared.
    estop: bool,
    /// The collision seen at the last step (errors are raised on a new contact only).
    in_contact: bool,
    /// The last collision that raised an error.
    pub last_collision: Option<Collision>,
    pub servo_commands: u64,
    pub commands: u64,
    /// Registers the box did not know (first 32), for diagnosis.
    pub unknown_registers: Vec<u8>,
    report_counter: u32,
}

fn put_f32s(out: &mut [u8], values: &[f64]) -> usize {
    for (i, v) in values.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&(*v as f32).to_le_bytes());
    }
    4 * values.len()
}

fn read_joints(params: &[u8]) -> Option<Joints> {
    if params.len() < 28 {
        return None;
    }
    let mut q = [0.0; DOF];
    for (j, v) in q.iter_mut().enumerate() {
        let b = [params[4 * j], params[4 * j + 1], params[4 * j + 2], params[4 * j + 3]];
        *v = f64::from(f32::from_le_bytes(b));
    }
    Some(q)
}

fn read_f32(params: &[u8], index: usize) -> Option<f64> {
    let b = params.get(4 * index..4 * index + 4)?;
    Some(f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
}

impl ArmBox {
    /// A box at power-up: motors off, stopped, mode 0, the arm resting at `initial_q`; it
    /// enforces `limits` (the joint-limit table of the arm `identity` names) and answers with
    /// `identity` (validate it first: text that does not fit is cut).
    pub fn new(
        mut plant: Box<dyn Plant>,
        initial_q: Joints,
        limits: [(f64, f64); DOF],
        identity: BoxIdentityConfig,
    ) -> Self {
        plant.reset(&initial_q);
        let mut version_text = identity.version_text();
        version_text.truncate(MAX_VERSION_TEXT);
        let checks_tcp_speed = identity.firmware_number().is_some_and(|v| v >= (2, 3, 0));
        Self {
            plant,
            limits,
            identity,
            version_text,
            checks_tcp_speed,
            last_servo_s: None,
            enabled: false,
            state: arm_state::STOPPED,
            mode: mode::POSITION,
            error: 0,
            warn: 0,
            target: initial_q,
            moving_to: None,
            deviation: 0.0,
            estop: false,
            in_contact: false,
            last_collision: None,
            servo_commands: 0,
            commands: 0,
            unknown_registers: Vec::new(),
            report_counter: 0,
        }
    }

    pub fn status(&self) -> BoxStatus {
        BoxStatus {
            enabled: self.enabled,
            state: self.state,
            mode: self.mode,
            error_code: self.error,
            warn_code: self.warn,
        }
    }

    /// The plant, for the camera and tests.
    pub fn plant_mut(&mut self) -> &mut dyn Plant {
        self.plant.as_mut()
    }

    /// The plant's true joints (without injected deviation).
    pub fn plant_joints(&self) -> Joints {
        self.plant.joints()
    }

    /// Joints as the box reports them (with injected deviation).
    pub fn reported_joints(&self) -> Joints {
        let mut q = self.plant.joints();
        for v in &mut q {
            *v += self.deviation;
        }
        q
    }

    fn ready(&self) -> bool {
        self.enabled
            && self.error == 0
            && matches!(self.state, arm_state::MOVING | arm_state::SLEEPING)
    }

    fn state_byte(&self) -> u8 {
        let mut s = 0;
        if self.error != 0 {
            s |= reg::STATE_ERROR;
        }
        if self.warn != 0 {
            s |= reg::STATE_WARNING;
        }
        if !self.ready() {
            s |= reg::STATE_NOT_READY;
        }
        s
    }

    /// Hold the arm where it is.
    fn hold(&mut self) {
        self.moving_to = None;
        self.target = self.plant.joints();
        self.plant.command(&self.target);
    }

    /// Raise a controller error: the box stops the arm.
    pub fn raise_error(&mut self, code: u8) {
        if self.error == 0 {
            self.error = code;
        }
        self.state = arm_state::STOPPED;
        self.hold();
    }

    pub fn set_deviation(&mut self, rad: f64) {
        self.deviation = rad;
    }

    /// The e-stop input changed: pressing it raises error 2 (emergency IO) and stops the arm.
    pub fn set_estop(&mut self, pressed: bool) {
        self.estop = pressed;
        if pressed {
            self.raise_error(codes::ERR_ESTOP_IO);
            self.enabled = false;
        }
    }

    fn beyond_limits(&self, q: &Joints) -> bool {
        q.iter().zip(self.limits.iter()).any(|(v, (lo, hi))| !(*v >= *lo && *v <= *hi))
    }

    /// A "system reset" (registers 11, 16, 18, 19 and set_state(4)): the ongoing motion ends
    /// and the command cache is cleared, "the same as the STOP state"; the arm moves again only
    /// after set_state(0).
    fn system_reset(&mut self) {
        self.state = arm_state::STOPPED;
        self.hold();
        self.last_servo_s = None;
    }

    /// Answer one request handled at `now_s` (seconds on any monotonic clock: servo_j speeds
    /// are measured on it).
    pub fn handle(&mut self, register: u8, params: &[u8], now_s: f64) -> BoxReply {
        self.commands += 1;
        let mut data = [0u8; MAX_REPLY_DATA];
        let mut invalid = false;
        let len = if let Some(len) = self.query(register, params, &mut data) {
            len
        } else if self.command(register, params, now_s, &mut invalid) {
            0
        } else {
            if self.unknown_registers.len() < 32 && !self.unknown_registers.contains(&register) {
                self.unknown_registers.push(register);
            }
            // Warning 13, "command does not exist"; the reply also says invalid.
            self.warn = codes::WARN_NO_SUCH_COMMAND;
            invalid = true;
            0
        };
        let mut state = self.state_byte();
        if invalid {
            state |= reg::STATE_INVALID;
        }
        BoxReply { state, len, data }
    }

    /// A report register: writes its reply into `data` and gives the reply's length; `None`
    /// when `register` is not a report.
    fn query(&self, register: u8, params: &[u8], data: &mut [u8; MAX_REPLY_DATA]) -> Option<usize> {
        let len = match register {
            reg::GET_VERSION => {
                let v = self.version_text.as_bytes();
                data[..v.len()].copy_from_slice(v);
                40
            }
            reg::GET_ROBOT_SN => {
                let (a, b) = (self.identity.arm_sn.as_bytes(), self.identity.box_sn.as_bytes());
                let (a, b) = (&a[..a.len().min(MAX_SN_LEN)], &b[..b.len().min(MAX_SN_LEN)]);
                data[..a.len()].copy_from_slice(a);
                data[a.len() + 1..a.len() + 1 + b.len()].copy_from_slice(b);
                40
            }
            reg::CHECK_VERIFY
            | reg::GET_REPORT_TAU_OR_I
            | reg::GET_ALLOW_APPROX_MOTION
            | reg::GET_SAFE_LEVEL => 1,
            reg::GET_HD_TYPES => 2,
            reg::GET_STATE => {
                data[0] = self.state;
                1
            }
            reg::GET_CMDNUM => 2,
            reg::GET_ERROR => {
                data[0] = self.error;
                data[1] = self.warn;
                2
            }
            reg::GET_TCP_POSE => put_f32s(data, &tcp_pose(&self.reported_joints())),
            reg::GET_JOINT_POS => {
                let q = self.reported_joints();
                match params.first().map(|n| n & 0x0F) {
                    None | Some(0 | 1) => put_f32s(data, &q),
                    Some(n) => {
                        let mut at = put_f32s(data, &q);
                        at += put_f32s(&mut data[at..], &self.plant.velocities());
                        if n >= 3 {
                            at += put_f32s(&mut data[at..], &[0.0; DOF]);
                        }
                        at
                    }
                }
            }
            reg::GET_JOINT_TAU => put_f32s(data, &[0.0; DOF]),
            _ => return None,
        };
        Some(len)
    }

    /// A command register: changes the box's state (`invalid` when its parameters are wrong);
    /// false when `register` is not a command.
    fn command(&mut self, register: u8, params: &[u8], now_s: f64, invalid: &mut bool) -> bool {
        match register {
            reg::MOTION_EN => match params {
                [axis @ 1..=8, en @ (0 | 1)] => {
                    if *en == 0 {
                        self.enabled = false;
                    } else if *axis == 8 && !self.estop {
                        self.enabled = true;
                    }
                    self.system_reset();
                }
                _ => *invalid = true,
            },
            reg::SET_STATE => match params {
                [arm_state::START] => {
                    if self.enabled && self.error == 0 {
                        if !matches!(self.state, arm_state::MOVING | arm_state::SLEEPING) {
                            self.hold();
                            self.last_servo_s = None;
                        }
                        self.state = arm_state::SLEEPING;
                    }
                }
                [arm_state::PAUSED] => {
                    if self.ready() {
                        self.state = arm_state::PAUSED;
                        self.hold();
                    }
                }
                [arm_state::STOPPED] => self.system_reset(),
                _ => *invalid = true,
            },
            reg::CLEAN_ERR => {
                if params.is_empty() {
                    if !self.estop {
                        self.error = 0;
                    }
                    self.system_reset();
                } else {
                    *invalid = true;
                }
            }
            reg::CLEAN_WAR => {
                if params.is_empty() {
                    self.warn = 0;
                } else {
                    *invalid = true;
                }
            }
            reg::SET_BRAKE => {
                match params {
                    [1..=8, value @ (0 | 1)] => {
                        // 0 "disable joint": a joint without power is not enabled.
                        if *value == 0 {
                            self.enabled = false;
                        }
                        self.system_reset();
                    }
                    _ => *invalid = true,
                }
            }
            reg::SET_MODE => match params {
                [m @ (mode::POSITION | mode::SERVO)] | [m @ (mode::POSITION | mode::SERVO), _] => {
                    self.mode = *m;
                    self.system_reset();
                }
                _ => *invalid = true,
            },
            reg::MOVE_SERVOJ => {
                self.servo_j(params, now_s, invalid);
            }
            reg::MOVE_JOINT => {
                self.move_joint(params, invalid);
            }
            _ => return false,
        }
        true
    }

    fn servo_j(&mut self, params: &[u8], now_s: f64, invalid: &mut bool) {
        let Some(q) = read_joints(params) else {
            *invalid = true;
            return;
        };
        if params.len() != 40 {
            *invalid = true;
            return;
        }
        if self.mode != mode::SERVO || !self.ready() {
            return;
        }
        if q.iter().any(|v| !v.is_finite()) || self.beyond_limits(&q) {
            self.raise_error(codes::ERR_JOINT_LIMIT);
            return;
        }
        // The step from the last target, over the time since it (one box period at least).
        let dt = match self.last_servo_s {
            Some(t) => (now_s - t).clamp(BOX_PERIOD_S, MAX_STEP_INTERVAL_S),
            None => MAX_STEP_INTERVAL_S,
        };
        let step = q.iter().zip(self.target.iter()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        if step / dt > MAX_JOINT_SPEED {
            self.raise_error(codes::ERR_SPEED_LIMIT);
            return;
        }
        if self.checks_tcp_speed {
            let p = |q: &Joints| hitl_trajectories::kinematics::flange_pose(q).translation.vector;
            if (p(&q) - p(&self.target)).norm() / dt > MAX_SERVO_J_TCP_SPEED {
                self.raise_error(codes::ERR_SERVOJ_LINEAR_SPEED);
                return;
            }
        }
        self.servo_commands += 1;
        self.last_servo_s = Some(now_s);
        self.moving_to = None;
        self.target = q;
        self.plant.command(&q);
    }

    fn move_joint(&mut self, params: &[u8], invalid: &mut bool) {
        let (Some(q), Some(speed)) = (read_joints(params), read_f32(params, 7)) else {
            *invalid = true;
            return;
        };
        if self.mode != mode::POSITION || !self.ready() {
            return;
        }
        if q.iter().any(|v| !v.is_finite()) || self.beyond_limits(&q) {
            self.raise_error(codes::ERR_JOINT_LIMIT);
            return;
        }
        let speed =
            if speed.is_finite() && speed > 0.0 { speed.min(MAX_JOINT_SPEED) } else { 0.35 };
        self.moving_to = Some((q, speed));
    }

    /// Advance the box and the plant by `dt` seconds.
    pub fn step(&mut self, dt: f64) {
        if let Some((goal, speed)) = self.moving_to {
            let mut done = true;
            let span =
                goal.iter().zip(self.target.iter()).map(|(g, t)| (g - t).abs()).fold(0.0, f64::max);
            let frac = if span > 0.0 { (speed * dt / span).min(1.0) } else { 1.0 };
            for (t, g) in self.target.iter_mut().zip(goal.iter()) {
                *t += (g - *t) * frac;
                done &= (g - *t).abs() < 1e-9;
            }
            self.plant.command(&self.target);
            if done {
                self.moving_to = None;
            }
        }
        self.plant.advance(dt);
        match self.plant.collision() {
            Some(c) => {
                if !self.in_contact && self.enabled && self.error == 0 {
                    self.raise_error(codes::ERR_COLLISION);
                    self.last_collision = Some(c);
                }
                self.in_contact = true;
            }
            None => self.in_contact = false,
        }
        if self.enabled && self.error == 0 {
            let fast =
                self.plant.velocities().iter().any(|v| v.is_nan() || v.abs() > MAX_JOINT_SPEED);
            if fast {
                self.raise_error(codes::ERR_FEEDBACK_SPEED);
            }
        }
        if matches!(self.state, arm_state::MOVING | arm_state::SLEEPING) {
            let moving = self.plant.velocities().iter().any(|v| v.abs() > MOVING_SPEED)
                || self.moving_to.is_some();
            self.state = if moving { arm_state::MOVING } else { arm_state::SLEEPING };
        }
    }

    /// What a report says now.
    pub fn report(&mut self, timestamp_us: u64) -> ReportData {
        self.report_counter = self.report_counter.wrapping_add(1);
        let q = self.reported_joints();
        let mask = if self.enabled { 0x7F } else { 0 };
        ReportData {
            state: self.state,
            mode: self.mode,
            cmd_num: 0,
            q,
            qd: self.plant.velocities(),
            target_q: self.target,
            tcp_pose: tcp_pose(&q),
            error_code: self.error,
            warn_code: self.warn,
            brake_mask: mask,
            enable_mask: mask,
            timestamp_us,
            counter: self.report_counter,
        }
    }

    pub fn identity(&self) -> BoxIdentity<'_> {
        BoxIdentity {
            robot_type: 7,
            axis: 7,
            version: &self.identity.firmware,
            joint_limits: self.limits,
        }
    }

    /// The serial numbers and firmware the box answers with.
    pub fn identity_config(&self) -> &BoxIdentityConfig {
        &self.identity
    }

    /// The joint limits the box enforces.
    pub fn joint_limits(&self) -> [(f64, f64); DOF] {
        self.limits
    }
}

/// The TCP (flange) pose as the box reports it: x, y, z in mm, roll, pitch, yaw in rad.
pub fn tcp_pose(q: &Joints) -> [f64; 6] {
    let pose = hitl_trajectories::kinematics::flange_pose(q);
    let t: Vector3<f64> = pose.translation.vector * 1000.0;
    let (roll, pitch, yaw) = pose.rotation.euler_angles();
    [t.x, t.y, t.z, roll, pitch, yaw]
}
