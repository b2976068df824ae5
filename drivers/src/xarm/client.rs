//! The command-socket client: one TCP connection to port 502, transaction ids, request/reply,
//! and the servo_j hot path. Implements [`hitl_hal::Arm`].
//!
//! Servo setpoints are *pipelined* by default: `servo_joint` drains whatever replies have
//! arrived (without blocking), checks their state bits, and writes the next setpoint; it never
//! waits for a round trip inside the tick. The official Python SDK instead waits for each reply;
//! [`ServoReplies::Wait`] does the same when wanted (benchmarks, comparison).
//!
//! [`Arm::stop`] never waits either: it writes set_state(4) from a buffer it owns and returns;
//! its reply is counted as outstanding and discarded when it arrives (a stop supervisor repeats
//! it until the reports show state 4). Every reply must carry the protocol id its request was
//! sent with (this client sends 0x0002 only) and the request's register.

use super::codec::{
    self, decode_reply, encode_request, encode_servo_j, frame_len, Accept, StateBits,
    PROTOCOL_PRIVATE, SERVO_J_LEN,
};
use super::error::XarmError;
use super::framing::FrameAccumulator;
use super::registers::{self as reg, arm_state};
use hitl_hal::{Arm, ErrorType, Joints, DOF};
use socket2::{Domain, Protocol, SockRef, Socket, TcpKeepalive, Type};
use std::io::{self, Write};
use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The box's command port.
pub const COMMAND_PORT: u16 = 502;
/// Receive buffer: several replies fit; anything larger than a frame is an error, not growth.
const RX_CAP: usize = 4096;
/// Largest reply data kept from a request (version strings are 40 bytes, joint tables 28).
const REPLY_DATA_CAP: usize = 128;
/// How long motion_enable waits for its reply at least (the official SDK raised its own to 5 s:
/// the box answers only once the motors are powered).
pub const MOTION_ENABLE_TIMEOUT: Duration = Duration::from_secs(5);
/// Bytes of a set_state request.
const SET_STATE_LEN: usize = codec::REQUEST_HEADER_LEN + 1;

/// How `servo_joint` treats the replies to its setpoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServoReplies {
    /// Write and return; check replies as they arrive on later calls. Fails when
    /// `max_outstanding` replies are missing (the box stopped answering).
    Pipelined { max_outstanding: u32 },
    /// Wait for each reply, like the official SDK (up to `reply_timeout`).
    Wait,
}

/// Connection settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientConfig {
    pub connect_timeout: Duration,
    /// How long a request waits for its reply (the SDK uses 2 s).
    pub reply_timeout: Duration,
    /// Bound on a blocking write (the tick's socket write).
    pub write_timeout: Duration,
    /// TCP keepalive idle time.
    pub keepalive: Duration,
    pub servo_replies: ServoReplies,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            connect_timeout: Duration::from_secs(2),
            reply_timeout: Duration::from_secs(2),
            write_timeout: Duration::from_millis(20),
            keepalive: Duration::from_secs(5),
            servo_replies: ServoReplies::Pipelined { max_outstanding: 25 },
        }
    }
}

/// A reply's state byte and a copy of its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplyData {
    pub register: u8,
    pub state: StateBits,
    len: usize,
    data: [u8; REPLY_DATA_CAP],
}

impl ReplyData {
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len]
    }
}

/// A connection to an xArm control box's command port.
#[derive(Debug)]
pub struct XarmClient {
    sock: Socket,
    peer: SocketAddr,
    config: ClientConfig,
    rx: FrameAccumulator<RX_CAP>,
    next_transaction: u16,
    servo_buf: [u8; SERVO_J_LEN],
    stop_buf: [u8; SET_STATE_LEN],
    /// Replies not waited for (pipelined servo_j and stop requests) not yet received.
    outstanding: u32,
    /// State byte of the most recent reply of any kind.
    last_state: StateBits,
    /// A fault seen in a servo_j reply, reported by the next `servo_joint`.
    servo_fault: Option<StateBits>,
    servo_sent: u64,
    /// Request frames written, shared with [`XarmClient::written_counter`]'s readers.
    written: Arc<AtomicU64>,
}

fn cmd_frame_len(buf: &[u8]) -> Result<Option<usize>, codec::CodecError> {
    frame_len(buf, Accept::Private)
}

impl XarmClient {
    /// Connect to `host` (name or address) on the command port 502.
    pub fn connect_host(host: &str, config: ClientConfig) -> Result<Self, XarmError> {
        let addr =
            (host, COMMAND_PORT).to_socket_addrs().map_err(XarmError::Io)?.next().ok_or_else(
                || {
                    XarmError::Io(io::Error::new(
                        io::ErrorKind::NotFound,
                        format!("no address for {host}"),
                    ))
                },
            )?;
        Self::connect(addr, config)
    }

    /// Connect to a command port at `addr`.
    pub fn connect(addr: SocketAddr, config: ClientConfig) -> Result<Self, XarmError> {
        let connect_err = |source| XarmError::Connect { addr, source };
        let sock = Socket::new(Domain::for_address(addr), Type::STREAM, Some(Protocol::TCP))
            .map_err(connect_err)?;
        sock.connect_timeout(&addr.into(), config.connect_timeout).map_err(connect_err)?;
        sock.set_tcp_nodelay(true).map_err(connect_err)?;
        let keepalive = TcpKeepalive::new()
            .with_time(config.keepalive)
            .with_interval(Duration::from_secs(1))
            .with_retries(3);
        sock.set_tcp_keepalive(&keepalive).map_err(connect_err)?;
        sock.set_write_timeout(Some(config.write_timeout)).map_err(connect_err)?;
        sock.set_read_timeout(Some(config.reply_timeout)).map_err(connect_err)?;
        Ok(Self {
            sock,
            peer: addr,
            config,
            rx: FrameAccumulator::new(),
            next_transaction: 1,
            servo_buf: [0; SERVO_J_LEN],
            stop_buf: [0; SET_STATE_LEN],
            outstanding: 0,
            last_state: StateBits(0),
            servo_fault: None,
            servo_sent: 0,
            written: Arc::new(AtomicU64::new(0)),
        })
    }

    /// The command port this client talks to.
    pub fn peer(&self) -> SocketAddr {
        self.peer
    }

    /// State byte of the most recent reply.
    pub fn last_state(&self) -> StateBits {
        self.last_state
    }

    /// servo_j setpoints written so far.
    pub fn servo_sent(&self) -> u64 {
        self.servo_sent
    }

    /// The count of request frames this client has written, readable from another thread (a
    /// simulated box in lockstep waits until it has answered as many as were written).
    pub fn written_counter(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.written)
    }

    /// Replies not waited for (servo_j setpoints, stop requests) not yet received.
    pub fn outstanding(&self) -> u32 {
        self.outstanding
    }

    /// Change how servo_j replies are handled.
    pub fn set_servo_replies(&mut self, mode: ServoReplies) {
        self.config.servo_replies = mode;
    }

    fn take_transaction(&mut self) -> u16 {
        let t = self.next_transaction;
        // Same sequence as the SDK: 1..=65535, then wrap to 1.
        self.next_transaction = t % u16::MAX + 1;
        t
    }

    /// Account for one reply frame that is not the one being waited for: a pipelined servo_j's
    /// or a stop's (every other request is waited for).
    fn note_other_reply(&mut self, register: u8, state: StateBits) {
        self.last_state = state;
        if register == reg::SET_STATE {
            self.outstanding = self.outstanding.saturating_sub(1);
        }
        if register == reg::MOVE_SERVOJ {
            self.outstanding = self.outstanding.saturating_sub(1);
            if (state.error() || state.not_ready() || state.invalid()) && self.servo_fault.is_none()
            {
                self.servo_fault = Some(state);
            }
        }
    }

    /// Read once (blocking up to the socket's read timeout) into the receive buffer.
    fn fill(&mut self) -> Result<(), XarmError> {
        let mut stream = &self.sock;
        match self.rx.fill_from(&mut stream) {
            Ok(0) => Err(XarmError::Closed),
            Ok(_) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                Err(XarmError::Codec(codec::CodecError::Overflow(self.rx.pending())))
            }
            Err(e) => Err(XarmError::Io(e)),
        }
    }

    /// Process every complete frame in the receive buffer that is not `want`; returns the
    /// wanted reply when found.
    fn scan(&mut self, want: Option<(u16, u8)>) -> Result<Option<ReplyData>, XarmError> {
        while self.rx.poll_frame(cmd_frame_len)?.is_some() {
            let r = decode_reply(self.rx.frame())?;
            if r.register == reg::FEEDBACK {
                continue;
            }
            if r.protocol != PROTOCOL_PRIVATE {
                return Err(codec::CodecError::ProtocolMismatch {
                    got: r.protocol,
                    want: PROTOCOL_PRIVATE,
                }
                .into());
            }
            if let Some((t, register)) = want {
                if r.transaction == t {
                    if r.register != register {
                        return Err(codec::CodecError::RegisterMismatch {
                            got: r.register,
                            want: register,
                        }
                        .into());
                    }
                    self.last_state = r.state;
                    let mut out = ReplyData {
                        register: r.register,
                        state: r.state,
                        len: r.data.len().min(REPLY_DATA_CAP),
                        data: [0; REPLY_DATA_CAP],
                    };
                    out.data[..out.len].copy_from_slice(&r.data[..out.len]);
                    return Ok(Some(out));
                }
            }
            self.note_other_reply(r.register, r.state);
        }
        Ok(None)
    }

    /// Read every reply already received without blocking.
    fn drain_nonblocking(&mut self) -> Result<(), XarmError> {
        self.scan(None)?;
        self.sock.set_nonblocking(true)?;
        let result = loop {
            match self.fill() {
                Ok(()) => {
                    if let Err(e) = self.scan(None) {
                        break Err(e);
                    }
                }
                Err(XarmError::Io(e)) if e.kind() == io::ErrorKind::WouldBlock => break Ok(()),
                Err(e) => break Err(e),
            }
        };
        self.sock.set_nonblocking(false)?;
        result
    }

    fn wait_reply(&mut self, transaction: u16, register: u8) -> Result<ReplyData, XarmError> {
        self.wait_reply_for(transaction, register, self.config.reply_timeout)
    }

    fn wait_reply_for(
        &mut self,
        transaction: u16,
        register: u8,
        timeout: Duration,
    ) -> Result<ReplyData, XarmError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(r) = self.scan(Some((transaction, register)))? {
                return Ok(r);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(XarmError::NoReply {
                    register: reg::name(register),
                    timeout_ms: timeout.as_millis() as u64,
                });
            }
            self.sock.set_read_timeout(Some(left.max(Duration::from_micros(100))))?;
            match self.fill() {
                Ok(()) => {}
                Err(XarmError::Io(e))
                    if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// Send one request and wait for its reply. Not for the hot path.
    pub fn request(&mut self, register: u8, params: &[u8]) -> Result<ReplyData, XarmError> {
        self.request_for(register, params, self.config.reply_timeout)
    }

    /// Send one request and wait up to `timeout` for its reply.
    pub fn request_for(
        &mut self,
        register: u8,
        params: &[u8],
        timeout: Duration,
    ) -> Result<ReplyData, XarmError> {
        let mut buf = [0u8; codec::MAX_FRAME_LEN];
        let t = self.take_transaction();
        let n = encode_request(&mut buf, t, PROTOCOL_PRIVATE, register, params)?;
        (&self.sock).write_all(&buf[..n])?;
        self.written.fetch_add(1, Ordering::Relaxed);
        let reply = self.wait_reply_for(t, register, timeout)?;
        if reply.state.invalid() {
            return Err(XarmError::Invalid { register: reg::name(register) });
        }
        Ok(reply)
    }

    /// Firmware version text (e.g. `7,7,XS...,XX...,v2.5.0`).
    pub fn version(&mut self) -> Result<String, XarmError> {
        let r = self.request(reg::GET_VERSION, &[])?;
        Ok(String::from_utf8_lossy(codec::nul_terminated(r.data())).into_owned())
    }

    /// Arm serial number.
    pub fn serial_number(&mut self) -> Result<String, XarmError> {
        let r = self.request(reg::GET_ROBOT_SN, &[])?;
        Ok(String::from_utf8_lossy(codec::nul_terminated(r.data())).into_owned())
    }

    /// The arm's state (1 moving, 2 sleeping, 3 paused, 4 stopped).
    pub fn state(&mut self) -> Result<u8, XarmError> {
        let r = self.request(reg::GET_STATE, &[])?;
        r.data().first().copied().ok_or_else(|| {
            codec::CodecError::Payload { register: reg::GET_STATE, got: 0, need: 1 }.into()
        })
    }

    /// Enable (or disable) every motor; waits [`MOTION_ENABLE_TIMEOUT`] (or the configured
    /// reply timeout, if longer) for the reply. A system reset: the arm is stopped afterwards.
    pub fn motion_enable(&mut self, enable: bool) -> Result<StateBits, XarmError> {
        let timeout = self.config.reply_timeout.max(MOTION_ENABLE_TIMEOUT);
        Ok(self.request_for(reg::MOTION_EN, &[8, u8::from(enable)], timeout)?.state)
    }

    /// Write set_state(4) and return without waiting for the reply (counted as outstanding,
    /// discarded when it arrives). Allocates nothing; blocks at most the write timeout.
    pub fn request_stop(&mut self) -> Result<(), XarmError> {
        // Take the replies already here first (never blocks); a broken reply stream must not
        // keep the stop from being written, so its error waits until after the write.
        let drained = self.drain_nonblocking();
        let t = self.take_transaction();
        let n = encode_request(
            &mut self.stop_buf,
            t,
            PROTOCOL_PRIVATE,
            reg::SET_STATE,
            &[arm_state::STOPPED],
        )?;
        (&self.sock).write_all(&self.stop_buf[..n])?;
        self.written.fetch_add(1, Ordering::Relaxed);
        self.outstanding += 1;
        drained
    }

    pub fn set_mode(&mut self, mode: u8) -> Result<StateBits, XarmError> {
        Ok(self.request(reg::SET_MODE, &[mode, 0])?.state)
    }

    pub fn set_state(&mut self, state: u8) -> Result<StateBits, XarmError> {
        Ok(self.request(reg::SET_STATE, &[state])?.state)
    }

    pub fn clean_error(&mut self) -> Result<StateBits, XarmError> {
        Ok(self.request(reg::CLEAN_ERR, &[])?.state)
    }

    pub fn clean_warn(&mut self) -> Result<StateBits, XarmError> {
        Ok(self.request(reg::CLEAN_WAR, &[])?.state)
    }

    /// Point-to-point joint move in mode 0 (speed rad/s, acceleration rad/s^2).
    pub fn move_joint(&mut self, q: &Joints, speed: f32, acc: f32) -> Result<StateBits, XarmError> {
        let mut buf = [0u8; SERVO_J_LEN];
        let t = self.take_transaction();
        codec::encode_joint_motion(&mut buf, t, reg::MOVE_JOINT, q, speed, acc, 0.0);
        (&self.sock).write_all(&buf)?;
        self.written.fetch_add(1, Ordering::Relaxed);
        let r = self.wait_reply(t, reg::MOVE_JOINT)?;
        check_motion_reply(reg::MOVE_JOINT, r.state)?;
        Ok(r.state)
    }

    /// Write one servo_j setpoint and wait for its reply (the SDK's behaviour).
    pub fn servo_joint_wait(&mut self, q: &Joints) -> Result<StateBits, XarmError> {
        let t = self.take_transaction();
        encode_servo_j(&mut self.servo_buf, t, q);
        (&self.sock).write_all(&self.servo_buf)?;
        self.written.fetch_add(1, Ordering::Relaxed);
        self.servo_sent += 1;
        let r = self.wait_reply(t, reg::MOVE_SERVOJ)?;
        check_motion_reply(reg::MOVE_SERVOJ, r.state)?;
        Ok(r.state)
    }

    /// Write one servo_j setpoint without waiting; replies are checked on later calls.
    pub fn servo_joint_pipelined(
        &mut self,
        q: &Joints,
        max_outstanding: u32,
    ) -> Result<(), XarmError> {
        self.drain_nonblocking()?;
        if let Some(state) = self.servo_fault.take() {
            check_motion_reply(reg::MOVE_SERVOJ, state)?;
        }
        if self.outstanding >= max_outstanding {
            return Err(XarmError::Backlog(self.outstanding));
        }
        let t = self.take_transaction();
        encode_servo_j(&mut self.servo_buf, t, q);
        (&self.sock).write_all(&self.servo_buf)?;
        self.written.fetch_add(1, Ordering::Relaxed);
        self.outstanding += 1;
        self.servo_sent += 1;
        Ok(())
    }

    /// Wait until every pipelined servo_j reply has arrived (or the reply timeout passes).
    pub fn flush_servo_replies(&mut self) -> Result<(), XarmError> {
        let deadline = Instant::now() + self.config.reply_timeout;
        while self.outstanding > 0 {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(XarmError::Backlog(self.outstanding));
            }
            self.sock.set_read_timeout(Some(left))?;
            match self.fill() {
                Ok(()) => {
                    self.scan(None)?;
                }
                Err(XarmError::Io(e))
                    if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
                Err(e) => return Err(e),
            }
        }
        match self.servo_fault.take() {
            Some(state) => check_motion_reply(reg::MOVE_SERVOJ, state),
            None => Ok(()),
        }
    }

    /// Close the connection (both directions).
    pub fn shutdown(&self) {
        let _ = SockRef::from(&self.sock).shutdown(std::net::Shutdown::Both);
    }
}

/// The error a motion reply's state bits mean (warnings are not errors, as in the SDK).
fn check_motion_reply(register: u8, state: StateBits) -> Result<(), XarmError> {
    let name = reg::name(register);
    if state.invalid() {
        Err(XarmError::Invalid { register: name })
    } else if state.error() {
        Err(XarmError::ArmFault { register: name, state: state.0 })
    } else if state.not_ready() {
        Err(XarmError::NotReady { register: name, state: state.0 })
    } else {
        Ok(())
    }
}

impl ErrorType for XarmClient {
    type Error = XarmError;
}

impl Arm for XarmClient {
    fn enable_servo(&mut self) -> Result<(), XarmError> {
        self.flush_servo_replies().ok();
        self.clean_error()?;
        self.clean_warn()?;
        self.motion_enable(true)?;
        self.set_mode(reg::mode::SERVO)?;
        self.set_state(arm_state::START)?;
        let (code, warn) = self.codes()?;
        if code != 0 {
            return Err(XarmError::Controller { code, warn });
        }
        let state = self.state()?;
        if matches!(state, arm_state::STOPPED | 5) {
            return Err(XarmError::EnableFailed { state });
        }
        Ok(())
    }

    fn servo_joint(&mut self, q: &Joints) -> Result<(), XarmError> {
        match self.config.servo_replies {
            ServoReplies::Pipelined { max_outstanding } => {
                self.servo_joint_pipelined(q, max_outstanding)
            }
            ServoReplies::Wait => self.servo_joint_wait(q).map(|_| ()),
        }
    }

    /// set_state(4), not waiting for the reply: see [`XarmClient::request_stop`].
    fn stop(&mut self) -> Result<(), XarmError> {
        self.request_stop()
    }

    fn joint_positions(&mut self) -> Result<Joints, XarmError> {
        let r = self.request(reg::GET_JOINT_POS, &[])?;
        let mut q = [0.0; DOF];
        codec::read_f32s(r.data(), reg::GET_JOINT_POS, &mut q)?;
        Ok(q)
    }

    fn codes(&mut self) -> Result<(u8, u8), XarmError> {
        let r = self.request(reg::GET_ERROR, &[])?;
        match r.data() {
            [e, w, ..] => Ok((*e, *w)),
            d => {
                Err(codec::CodecError::Payload { register: reg::GET_ERROR, got: d.len(), need: 2 }
                    .into())
            }
        }
    }
}
