//! Report frames of the report ports (30000 real-time, 30001 normal, 30002 rich, 30003 real):
//! framing, decoding for the client, encoding for the stub.
//!
//! Every report starts with its total size (u32, big-endian), then a byte with the state (low
//! nibble) and mode (high nibble), the cached-command count (u16 BE) and the joints; integers are
//! big-endian, floats little-endian f32. Offsets follow the official SDK's report structures.

use super::codec::CodecError;
use hitl_hal::{Joints, DOF};

/// Smallest report a box sends (30003 before firmware 1.8; our decoder needs the joints).
pub const MIN_REPORT_LEN: usize = 87;
/// Largest report accepted; the 30000 report is 804 bytes in the SDK's newest layout.
pub const MAX_REPORT_LEN: usize = 1024;
/// Largest state a box reports (the SDK drops a normal/rich report stream above it).
pub const MAX_STATE: u8 = 9;
/// Largest mode a box reports (same).
pub const MAX_MODE: u8 = 11;
/// Largest collision and teach sensitivity (same).
pub const MAX_SENSITIVITY: u8 = 5;

/// A field outside what a box can send makes the whole report a fault, not data (the official
/// SDK closes the report stream on such a frame).
fn check_field(field: &'static str, value: u8, max: u8) -> Result<(), CodecError> {
    if value > max {
        Err(CodecError::ReportField { field, value, max })
    } else {
        Ok(())
    }
}

/// The report ports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReportKind {
    /// Port 30000, 200 Hz (firmware >= 2.1): target and actual joints, velocities, currents.
    RealTime,
    /// Port 30001, 5 Hz: joints, pose, motor and error/warning codes.
    Normal,
    /// Port 30002, 5 Hz: the normal report plus configuration, version, speeds, voltages.
    Rich,
    /// Port 30003, 100 Hz: state, mode, joints, pose, torques.
    Real,
}

impl ReportKind {
    pub const ALL: [ReportKind; 4] =
        [ReportKind::RealTime, ReportKind::Normal, ReportKind::Rich, ReportKind::Real];

    /// The box's TCP port for this report.
    pub fn default_port(self) -> u16 {
        match self {
            ReportKind::RealTime => 30000,
            ReportKind::Normal => 30001,
            ReportKind::Rich => 30002,
            ReportKind::Real => 30003,
        }
    }

    /// The report kind served on a default port.
    pub fn from_port(port: u16) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.default_port() == port)
    }

    /// Reports per second on a real box (UFACTORY's port documentation).
    pub fn rate_hz(self) -> f64 {
        match self {
            ReportKind::RealTime => 200.0,
            ReportKind::Normal | ReportKind::Rich => 5.0,
            ReportKind::Real => 100.0,
        }
    }

    /// Bytes of the frame the stub sends (the SDK's newest layout).
    pub fn frame_len(self) -> usize {
        match self {
            ReportKind::RealTime => 804,
            ReportKind::Normal => 145,
            ReportKind::Rich => 587,
            ReportKind::Real => 135,
        }
    }

    /// Whether this report carries the error and warning codes.
    pub fn has_codes(self) -> bool {
        matches!(self, ReportKind::Normal | ReportKind::Rich)
    }
}

/// What one report says (the fields the controller and the stub care about).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ReportData {
    pub state: u8,
    pub mode: u8,
    pub cmd_num: u16,
    /// Actual joint positions, rad.
    pub q: Joints,
    /// Actual joint velocities, rad/s (30000 and the rich report's speeds).
    pub qd: Joints,
    /// Target joint positions, rad (30000 only).
    pub target_q: Joints,
    /// TCP pose: x, y, z in mm, roll, pitch, yaw in rad.
    pub tcp_pose: [f64; 6],
    /// Error and warning codes (30001, 30002 only; 0 elsewhere).
    pub error_code: u8,
    pub warn_code: u8,
    /// Motor brake-released and enabled bit masks, bit i = joint i+1 (30001, 30002).
    pub brake_mask: u8,
    pub enable_mask: u8,
    /// Box timestamp, microseconds (30000 only).
    pub timestamp_us: u64,
    /// Free-running counter (rich report).
    pub counter: u32,
}

/// The declared size of the report at the start of `buf` (`Ok(None)` until 4 bytes arrived).
pub fn report_frame_len(buf: &[u8]) -> Result<Option<usize>, CodecError> {
    let [a, b, c, d, ..] = *buf else { return Ok(None) };
    let size = u32::from_be_bytes([a, b, c, d]) as usize;
    if !(MIN_REPORT_LEN..=MAX_REPORT_LEN).contains(&size) {
        return Err(CodecError::ReportSize(size));
    }
    Ok(Some(size))
}

fn f32_at(b: &[u8], at: usize) -> f64 {
    f64::from(f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]))
}

fn f32s<const N: usize>(b: &[u8], at: usize) -> [f64; N] {
    let mut out = [0.0; N];
    for (i, v) in out.iter_mut().enumerate() {
        *v = f32_at(b, at + 4 * i);
    }
    out
}

fn put_f32s(out: &mut [u8], at: usize, values: &[f64]) {
    for (i, v) in values.iter().enumerate() {
        out[at + 4 * i..at + 4 * i + 4].copy_from_slice(&(*v as f32).to_le_bytes());
    }
}

/// Decode a complete report frame of `kind`.
pub fn decode_report(frame: &[u8], kind: ReportKind) -> Result<ReportData, CodecError> {
    let size = report_frame_len(frame)?.ok_or(CodecError::Short { got: frame.len(), need: 4 })?;
    if frame.len() < size {
        return Err(CodecError::Short { got: frame.len(), need: size });
    }
    let frame = &frame[..size];
    let need = match kind {
        ReportKind::RealTime => 200,
        ReportKind::Normal | ReportKind::Rich => 91,
        ReportKind::Real => MIN_REPORT_LEN,
    };
    if size < need {
        return Err(CodecError::Short { got: size, need });
    }
    let mut r = ReportData::default();
    if kind == ReportKind::RealTime {
        let mut ts = [0u8; 8];
        ts.copy_from_slice(&frame[4..12]);
        r.timestamp_us = u64::from_be_bytes(ts);
        r.state = frame[12] & 0x0F;
        r.mode = frame[12] >> 4;
        check_field("state", r.state, MAX_STATE)?;
        check_field("mode", r.mode, MAX_MODE)?;
        r.cmd_num = u16::from_be_bytes([frame[13], frame[14]]);
        r.target_q = f32s(frame, 32);
        r.q = f32s(frame, 116);
        r.qd = f32s(frame, 144);
        if size >= 496 {
            r.tcp_pose = f32s(frame, 472);
        }
        return Ok(r);
    }
    r.state = frame[4] & 0x0F;
    r.mode = frame[4] >> 4;
    check_field("state", r.state, MAX_STATE)?;
    check_field("mode", r.mode, MAX_MODE)?;
    r.cmd_num = u16::from_be_bytes([frame[5], frame[6]]);
    r.q = f32s(frame, 7);
    r.tcp_pose = f32s(frame, 35);
    if kind.has_codes() {
        if size >= 133 {
            check_field("collision sensitivity", frame[131], MAX_SENSITIVITY)?;
            check_field("teach sensitivity", frame[132], MAX_SENSITIVITY)?;
        }
        r.brake_mask = frame[87];
        r.enable_mask = frame[88];
        r.error_code = frame[89];
        r.warn_code = frame[90];
    }
    if kind == ReportKind::Rich && size >= 288 {
        let speeds: [f64; DOF] = f32s(frame, 256);
        r.qd = speeds;
        r.counter = u32::from_be_bytes([frame[284], frame[285], frame[286], frame[287]]);
    }
    Ok(r)
}

/// Static facts a rich report carries about the box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxIdentity<'a> {
    /// Robot type (7 = xArm7 X4) and axis count.
    pub robot_type: u8,
    pub axis: u8,
    /// Firmware version text, at most 30 bytes.
    pub version: &'a str,
    /// Joint limits as [min, max] pairs, rad (reduced-mode joint ranges).
    pub joint_limits: [(f64, f64); DOF],
}

/// Write a report of `kind` into `out`; returns its length ([`ReportKind::frame_len`]).
pub fn encode_report(
    out: &mut [u8],
    kind: ReportKind,
    r: &ReportData,
    id: &BoxIdentity<'_>,
) -> Result<usize, CodecError> {
    let size = kind.frame_len();
    if out.len() < size {
        return Err(CodecError::BufferTooSmall { got: out.len(), need: size });
    }
    let out = &mut out[..size];
    out.fill(0);
    out[0..4].copy_from_slice(&(size as u32).to_be_bytes());
    let state_mode = (r.state & 0x0F) | (r.mode << 4);
    if kind == ReportKind::RealTime {
        out[4..12].copy_from_slice(&r.timestamp_us.to_be_bytes());
        out[12] = state_mode;
        out[13..15].copy_from_slice(&r.cmd_num.to_be_bytes());
        put_f32s(out, 32, &r.target_q);
        put_f32s(out, 116, &r.q);
        put_f32s(out, 144, &r.qd);
        put_f32s(out, 424, &r.tcp_pose);
        put_f32s(out, 472, &r.tcp_pose);
        return Ok(size);
    }
    out[4] = state_mode;
    out[5..7].copy_from_slice(&r.cmd_num.to_be_bytes());
    put_f32s(out, 7, &r.q);
    put_f32s(out, 35, &r.tcp_pose);
    if kind == ReportKind::Real {
        return Ok(size);
    }
    out[87] = r.brake_mask;
    out[88] = r.enable_mask;
    out[89] = r.error_code;
    out[90] = r.warn_code;
    // Collision and teach sensitivities (the SDK rejects reports with values above 5).
    out[131] = 3;
    out[132] = 3;
    put_f32s(out, 133, &[0.0, 0.0, -1.0]);
    if kind == ReportKind::Normal {
        return Ok(size);
    }
    out[145] = id.robot_type;
    out[146] = id.axis;
    out[147] = 0xAA;
    out[148] = 0x55;
    let v = id.version.as_bytes();
    let n = v.len().min(29);
    out[151..151 + n].copy_from_slice(&v[..n]);
    // TCP jerk, min/max acc, min/max speed; joint jerk, min/max acc, min/max speed; rotation.
    put_f32s(out, 181, &[10000.0, 0.1, 50000.0, 0.1, 1000.0]);
    put_f32s(out, 201, &[1000.0, 0.01, 20.0, 0.01, std::f64::consts::PI]);
    put_f32s(out, 221, &[0.0, 0.0]);
    for t in &mut out[245..252] {
        *t = 30;
    }
    put_f32s(out, 256, &r.qd);
    out[284..288].copy_from_slice(&r.counter.to_be_bytes());
    // Joint voltages x100 (48 V bus).
    for j in 0..DOF {
        out[341 + 2 * j..343 + 2 * j].copy_from_slice(&4800u16.to_be_bytes());
    }
    put_f32s(out, 482, &r.tcp_pose[3..6]);
    for (j, (lo, hi)) in id.joint_limits.iter().enumerate() {
        put_f32s(out, 516 + 8 * j, &[*lo, *hi]);
    }
    Ok(size)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_roundtrips() {
        let id = BoxIdentity {
            robot_type: 7,
            axis: 7,
            version: "7,7,XS1303,XX1303,v2.5.0",
            joint_limits: [(-1.0, 1.0); DOF],
        };
        let r = ReportData {
            state: 2,
            mode: 1,
            cmd_num: 3,
            q: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7],
            qd: [0.01; DOF],
            target_q: [0.15; DOF],
            tcp_pose: [200.0, 0.0, 100.0, 3.1, 0.0, 0.0],
            error_code: 23,
            warn_code: 0,
            brake_mask: 0x7f,
            enable_mask: 0x7f,
            timestamp_us: 123_456,
            counter: 9,
        };
        let mut buf = [0u8; MAX_REPORT_LEN];
        for kind in ReportKind::ALL {
            let n = encode_report(&mut buf, kind, &r, &id).expect("fits");
            assert_eq!(report_frame_len(&buf[..n]), Ok(Some(n)));
            let d = decode_report(&buf[..n], kind).expect("decodes");
            assert_eq!((d.state, d.mode), (2, 1));
            for j in 0..DOF {
                assert!((d.q[j] - r.q[j]).abs() < 1e-6);
            }
            if kind.has_codes() {
                assert_eq!((d.error_code, d.warn_code), (23, 0));
            }
            if kind == ReportKind::RealTime {
                assert_eq!(d.timestamp_us, 123_456);
                assert!((d.target_q[0] - 0.15).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn out_of_range_fields_are_faults_not_data() {
        let id = BoxIdentity {
            robot_type: 7,
            axis: 7,
            version: "v2.5.0",
            joint_limits: [(-1.0, 1.0); DOF],
        };
        let r = ReportData { state: 2, mode: 1, ..ReportData::default() };
        let mut buf = [0u8; MAX_REPORT_LEN];
        for kind in ReportKind::ALL {
            let n = encode_report(&mut buf, kind, &r, &id).expect("fits");
            let at = if kind == ReportKind::RealTime { 12 } else { 4 };
            buf[at] = 0x1A; // state 10
            assert_eq!(
                decode_report(&buf[..n], kind),
                Err(CodecError::ReportField { field: "state", value: 10, max: 9 })
            );
            buf[at] = 0xC2; // mode 12
            assert_eq!(
                decode_report(&buf[..n], kind),
                Err(CodecError::ReportField { field: "mode", value: 12, max: 11 })
            );
            buf[at] = 0xB9; // mode 11, state 9: the largest a box sends
            assert!(decode_report(&buf[..n], kind).is_ok());
            if kind.has_codes() {
                buf[131] = 6;
                assert_eq!(
                    decode_report(&buf[..n], kind),
                    Err(CodecError::ReportField {
                        field: "collision sensitivity",
                        value: 6,
                        max: 5
                    })
                );
                buf[131] = 5;
                buf[132] = 200;
                assert!(decode_report(&buf[..n], kind).is_err());
            }
        }
    }

    #[test]
    fn absurd_sizes_are_errors() {
        assert_eq!(report_frame_len(&[0, 0, 0, 3]), Err(CodecError::ReportSize(3)));
        assert_eq!(report_frame_len(&[0xff, 0, 0, 0]), Err(CodecError::ReportSize(0xff00_0000)));
        assert_eq!(report_frame_len(&[0, 0, 0]), Ok(None));
        assert_eq!(report_frame_len(&[0, 0, 0, 135, 1]), Ok(Some(135)));
    }
}
