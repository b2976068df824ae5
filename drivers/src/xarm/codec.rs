//! The command-socket protocol as pure functions over byte slices: requests, replies, framing.
//!
//! A frame is a private Modbus-TCP frame (all integers big-endian, floats little-endian):
//!
//! ```text
//! 0..2  transaction id      2..4  protocol id (0x0002; 0x0003 = private with heartbeat)
//! 4..6  length of the bytes that follow
//! 6     register (function)
//! 7..   request parameters | reply: 7 state byte, 8.. data
//! ```
//!
//! Encoders write into caller-owned buffers and never allocate. Decoders borrow from the input and
//! return [`CodecError`] on anything malformed; they never panic, whatever the bytes.

use super::registers;
use hitl_hal::{Joints, DOF};

/// Protocol id of the private protocol the SDK speaks.
pub const PROTOCOL_PRIVATE: u16 = 0x0002;
/// Protocol id of the private protocol with heartbeat (the SDK switches to it on firmware >= 1.8.6).
pub const PROTOCOL_PRIVATE_HEARTBEAT: u16 = 0x0003;
/// Protocol id of the SDK's heartbeat frames (`00 00 00 01 00 02 00 00`).
pub const PROTOCOL_HEARTBEAT: u16 = 0x0001;
/// Protocol id of standard Modbus-TCP.
pub const PROTOCOL_STANDARD: u16 = 0x0000;

/// Bytes before the length-counted part (transaction id, protocol id, length).
pub const PREFIX_LEN: usize = 6;
/// Bytes of a request header including the register.
pub const REQUEST_HEADER_LEN: usize = 7;
/// Bytes of a reply header including register and state byte.
pub const REPLY_HEADER_LEN: usize = 8;
/// Largest length field accepted. The SDK's largest frames (trajectory file names, DH tables)
/// stay well under it; anything above is garbage.
pub const MAX_LENGTH_FIELD: usize = 512;
/// Largest whole frame.
pub const MAX_FRAME_LEN: usize = PREFIX_LEN + MAX_LENGTH_FIELD;
/// Bytes of a servo_j request: header + 10 floats.
pub const SERVO_J_LEN: usize = REQUEST_HEADER_LEN + 40;

/// Why bytes could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CodecError {
    #[error("frame too short: {got} bytes, need {need}")]
    Short { got: usize, need: usize },
    #[error("unexpected protocol id {0:#06x}")]
    Protocol(u16),
    #[error("absurd length field {0}")]
    Length(usize),
    #[error("report frame size {0} outside the known report sizes")]
    ReportSize(usize),
    #[error("output buffer too small: {got} bytes, need {need}")]
    BufferTooSmall { got: usize, need: usize },
    #[error("frame buffer overflow: {0} bytes pending without a complete frame")]
    Overflow(usize),
    #[error("reply to register {got} while waiting for register {want}")]
    RegisterMismatch { got: u8, want: u8 },
    #[error("reply with protocol id {got:#06x} to a request sent with {want:#06x}")]
    ProtocolMismatch { got: u16, want: u16 },
    #[error("report field {field} = {value} out of range (at most {max})")]
    ReportField { field: &'static str, value: u8, max: u8 },
    #[error("report size changed from {first} to {got} bytes on one stream")]
    ReportSizeChanged { first: usize, got: usize },
    #[error("reply payload of register {register} too short: {got} bytes, need {need}")]
    Payload { register: u8, got: usize, need: usize },
}

/// The state byte of a reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StateBits(pub u8);

impl StateBits {
    pub fn error(self) -> bool {
        self.0 & registers::STATE_ERROR != 0
    }
    pub fn warning(self) -> bool {
        self.0 & registers::STATE_WARNING != 0
    }
    pub fn not_ready(self) -> bool {
        self.0 & registers::STATE_NOT_READY != 0
    }
    pub fn invalid(self) -> bool {
        self.0 & registers::STATE_INVALID != 0
    }
}

/// A decoded reply, borrowing its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reply<'a> {
    pub transaction: u16,
    pub protocol: u16,
    pub register: u8,
    pub state: StateBits,
    pub data: &'a [u8],
}

/// A decoded request, borrowing its parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request<'a> {
    pub transaction: u16,
    pub protocol: u16,
    pub register: u8,
    pub params: &'a [u8],
}

/// Which protocol ids a framer accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accept {
    /// A client: only the private protocol ids (2 and 3).
    Private,
    /// A server: standard (0), heartbeat (1) and private (2, 3).
    Any,
}

fn be16(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}

/// The declared total length of the frame at the start of `buf` (`Ok(None)` until its 6-byte
/// prefix has arrived), or an error when the prefix cannot start a valid frame. The frame is
/// complete once `buf.len()` reaches the returned length.
pub fn frame_len(buf: &[u8], accept: Accept) -> Result<Option<usize>, CodecError> {
    if buf.len() < PREFIX_LEN {
        return Ok(None);
    }
    let protocol = be16(buf, 2);
    let ok = match accept {
        Accept::Private => matches!(protocol, PROTOCOL_PRIVATE | PROTOCOL_PRIVATE_HEARTBEAT),
        Accept::Any => protocol <= PROTOCOL_PRIVATE_HEARTBEAT,
    };
    if !ok {
        return Err(CodecError::Protocol(protocol));
    }
    let length = usize::from(be16(buf, 4));
    if length == 0 || length > MAX_LENGTH_FIELD {
        return Err(CodecError::Length(length));
    }
    Ok(Some(PREFIX_LEN + length))
}

/// The complete frame at the start of `buf`, or why there is none.
fn whole_frame(buf: &[u8], accept: Accept) -> Result<usize, CodecError> {
    match frame_len(buf, accept)? {
        Some(total) if buf.len() >= total => Ok(total),
        Some(total) => Err(CodecError::Short { got: buf.len(), need: total }),
        None => Err(CodecError::Short { got: buf.len(), need: PREFIX_LEN }),
    }
}

/// Write a request with raw parameter bytes; returns the frame length.
pub fn encode_request(
    out: &mut [u8],
    transaction: u16,
    protocol: u16,
    register: u8,
    params: &[u8],
) -> Result<usize, CodecError> {
    let total = REQUEST_HEADER_LEN + params.len();
    if params.len() + 1 > MAX_LENGTH_FIELD {
        return Err(CodecError::Length(params.len() + 1));
    }
    if out.len() < total {
        return Err(CodecError::BufferTooSmall { got: out.len(), need: total });
    }
    write_prefix(out, transaction, protocol, params.len() + 1);
    out[6] = register;
    out[REQUEST_HEADER_LEN..total].copy_from_slice(params);
    Ok(total)
}

fn write_prefix(out: &mut [u8], transaction: u16, protocol: u16, length: usize) {
    out[0..2].copy_from_slice(&transaction.to_be_bytes());
    out[2..4].copy_from_slice(&protocol.to_be_bytes());
    // Callers bound `length` by MAX_LENGTH_FIELD, so it fits a u16.
    out[4..6].copy_from_slice(&(length.min(usize::from(u16::MAX)) as u16).to_be_bytes());
}

/// Write a servo_j (or move_joint, same layout) request: 7 joints, then speed, acceleration and
/// time, as little-endian f32. Allocates nothing; returns [`SERVO_J_LEN`].
pub fn encode_joint_motion(
    out: &mut [u8; SERVO_J_LEN],
    transaction: u16,
    register: u8,
    q: &Joints,
    speed: f32,
    acc: f32,
    mvtime: f32,
) -> usize {
    write_prefix(out, transaction, PROTOCOL_PRIVATE, SERVO_J_LEN - PREFIX_LEN);
    out[6] = register;
    let mut at = REQUEST_HEADER_LEN;
    for v in q.iter().map(|v| *v as f32).chain([speed, acc, mvtime]) {
        out[at..at + 4].copy_from_slice(&v.to_le_bytes());
        at += 4;
    }
    SERVO_J_LEN
}

/// Write a servo_j request for joints `q` (speed, acceleration and time are ignored in servo mode
/// and sent as 0, as the SDK does by default).
pub fn encode_servo_j(out: &mut [u8; SERVO_J_LEN], transaction: u16, q: &Joints) -> usize {
    encode_joint_motion(out, transaction, registers::MOVE_SERVOJ, q, 0.0, 0.0, 0.0)
}

/// Decode a complete reply frame (as delimited by [`frame_len`]).
pub fn decode_reply(frame: &[u8]) -> Result<Reply<'_>, CodecError> {
    let total = whole_frame(frame, Accept::Private)?;
    if total < REPLY_HEADER_LEN {
        return Err(CodecError::Short { got: total, need: REPLY_HEADER_LEN });
    }
    Ok(Reply {
        transaction: be16(frame, 0),
        protocol: be16(frame, 2),
        register: frame[6],
        state: StateBits(frame[7]),
        data: &frame[REPLY_HEADER_LEN..total],
    })
}

/// Decode a complete request frame (server side; any protocol id 0-3).
pub fn decode_request(frame: &[u8]) -> Result<Request<'_>, CodecError> {
    let total = whole_frame(frame, Accept::Any)?;
    Ok(Request {
        transaction: be16(frame, 0),
        protocol: be16(frame, 2),
        register: frame[6],
        params: &frame[REQUEST_HEADER_LEN..total],
    })
}

/// Write a reply (server side); returns the frame length.
pub fn encode_reply(
    out: &mut [u8],
    transaction: u16,
    protocol: u16,
    register: u8,
    state: u8,
    data: &[u8],
) -> Result<usize, CodecError> {
    let total = REPLY_HEADER_LEN + data.len();
    if data.len() + 2 > MAX_LENGTH_FIELD {
        return Err(CodecError::Length(data.len() + 2));
    }
    if out.len() < total {
        return Err(CodecError::BufferTooSmall { got: out.len(), need: total });
    }
    write_prefix(out, transaction, protocol, data.len() + 2);
    out[6] = register;
    out[7] = state;
    out[REPLY_HEADER_LEN..total].copy_from_slice(data);
    Ok(total)
}

/// Read `n` little-endian f32 values from `data` into `out` (as f64).
pub fn read_f32s(data: &[u8], register: u8, out: &mut [f64]) -> Result<(), CodecError> {
    let need = out.len() * 4;
    if data.len() < need {
        return Err(CodecError::Payload { register, got: data.len(), need });
    }
    for (i, v) in out.iter_mut().enumerate() {
        let b = [data[4 * i], data[4 * i + 1], data[4 * i + 2], data[4 * i + 3]];
        *v = f64::from(f32::from_le_bytes(b));
    }
    Ok(())
}

/// Joints from a get_joint_pos (42) reply.
pub fn decode_joints(reply: &Reply<'_>) -> Result<Joints, CodecError> {
    let mut q = [0.0; DOF];
    read_f32s(reply.data, reply.register, &mut q)?;
    Ok(q)
}

/// (error, warning) codes from a get_error (15) reply.
pub fn decode_codes(reply: &Reply<'_>) -> Result<(u8, u8), CodecError> {
    match reply.data {
        [e, w, ..] => Ok((*e, *w)),
        _ => Err(CodecError::Payload { register: reply.register, got: reply.data.len(), need: 2 }),
    }
}

/// The string in a NUL-padded byte field (version, serial numbers), lossy UTF-8.
pub fn nul_terminated(data: &[u8]) -> &[u8] {
    let end = data.iter().position(|b| *b == 0).unwrap_or(data.len());
    &data[..end]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn servo_j_bytes_match_the_sdk_layout() {
        let mut buf = [0u8; SERVO_J_LEN];
        let q = [0.5, -1.0, 0.0, 1.25, 0.0, 0.0, -0.25];
        let n = encode_servo_j(&mut buf, 0x0102, &q);
        assert_eq!(n, 47);
        assert_eq!(&buf[..7], &[0x01, 0x02, 0x00, 0x02, 0x00, 41, 29]);
        assert_eq!(&buf[7..11], &0.5f32.to_le_bytes());
        assert_eq!(&buf[11..15], &(-1.0f32).to_le_bytes());
        assert_eq!(&buf[31..35], &(-0.25f32).to_le_bytes());
        let req = decode_request(&buf).expect("valid request");
        assert_eq!(req.register, registers::MOVE_SERVOJ);
        assert_eq!(req.params.len(), 40);
    }

    #[test]
    fn reply_roundtrip_and_state_bits() {
        let mut buf = [0u8; 64];
        let n = encode_reply(&mut buf, 7, 2, registers::GET_ERROR, 0x40 | 0x10, &[23, 0])
            .expect("fits");
        assert_eq!(&buf[..n], &[0, 7, 0, 2, 0, 4, 15, 0x50, 23, 0]);
        let r = decode_reply(&buf[..n]).expect("valid");
        assert!(r.state.error() && r.state.not_ready() && !r.state.warning() && !r.state.invalid());
        assert_eq!(decode_codes(&r), Ok((23, 0)));
    }

    #[test]
    fn framing_rejects_garbage() {
        assert_eq!(frame_len(&[0, 1, 0, 9, 0, 2], Accept::Private), Err(CodecError::Protocol(9)));
        assert_eq!(
            frame_len(&[0, 1, 0, 2, 0xff, 0xff], Accept::Private),
            Err(CodecError::Length(65535))
        );
        assert_eq!(frame_len(&[0, 1, 0, 2, 0, 0], Accept::Private), Err(CodecError::Length(0)));
        assert_eq!(frame_len(&[0, 1, 0, 2, 0], Accept::Private), Ok(None));
        assert_eq!(frame_len(&[0, 1, 0, 2, 0, 3, 1], Accept::Private), Ok(Some(9)));
        assert_eq!(frame_len(&[0, 1, 0, 2, 0, 2, 1, 0, 9], Accept::Private), Ok(Some(8)));
        assert!(decode_reply(&[0, 1, 0, 2, 0, 1, 1]).is_err());
    }
}
