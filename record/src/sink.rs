//! The MCAP file itself: schemas, channels, and how each message becomes bytes.
//!
//! Project messages are JSON with a JSON Schema; images, calibration, transforms and poses use
//! Foxglove's well-known protobuf schemas (from the `foxglove` crate) so Foxglove and the
//! Python `mcap-protobuf-support` decoder read them as they are.

use crate::channels::{calibration, ts, Ch, CHANNELS};
use crate::compression::ChunkCompression;
use crate::error::RecordError;
use crate::metadata::RunMetadata;
use crate::msg::{
    metres_to_mm, ArmStateMsg, CaptureSyncMsg, DepthImage, EventDetail, FrameRecord, LightMsg,
    PoseStamped, SafetyEventMsg, SetpointMsg, TfMsg, TimingMsg, TriggerFiredMsg,
};
use crate::topics;
use foxglove::messages as fg;
use foxglove::Encode;
use hitl_hal::{pose, Pose};
use mcap::records::{MessageHeader, Metadata};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// How depth is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthOutput {
    /// As the camera delivered it (32FC1 metres or 16UC1 millimetres).
    #[default]
    AsDelivered,
    /// Always 16UC1 millimetres (half the bytes of 32FC1; 1 mm resolution, 65.5 m range).
    Millimetres16,
}

pub(crate) struct McapSink {
    w: mcap::Writer<BufWriter<File>>,
    ids: [u16; CHANNELS.len()],
    seq: [u32; CHANNELS.len()],
    pub written: [u64; CHANNELS.len()],
    buf: Vec<u8>,
    /// Message payload bytes handed to the writer (before compression).
    pub bytes_in: u64,
    depth_output: DepthOutput,
    /// The live view's tap (`hitl run --live`): every message written is offered to it.
    pub live: Option<crate::live::LiveTap>,
}

/// The Foxglove pose of a [`Pose`]: position in metres, orientation as the unit quaternion
/// (x, y, z, w), as every recording has carried it.
fn fg_pose(p: &Pose) -> fg::Pose {
    let [x, y, z] = p.translation.vector.into();
    let [qx, qy, qz, qw] = pose::quat_xyzw(p);
    fg::Pose {
        position: Some(fg::Vector3 { x, y, z }),
        orientation: Some(fg::Quaternion { x: qx, y: qy, z: qz, w: qw }),
    }
}

fn fg_transform(t_ns: u64, parent: &str, child: &str, p: &Pose) -> fg::FrameTransform {
    let fp = fg_pose(p);
    fg::FrameTransform {
        timestamp: ts(t_ns),
        parent_frame_id: parent.to_string(),
        child_frame_id: child.to_string(),
        translation: fp.position,
        rotation: fp.orientation,
    }
}

#[derive(Serialize)]
struct EventJson<'a> {
    t_ns: u64,
    kind: &'a str,
    detail: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    tick: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    joint: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    value: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    limit: Option<f64>,
}

impl McapSink {
    pub fn create(
        path: &Path,
        meta: &RunMetadata,
        compression: ChunkCompression,
        compression_threads: u32,
        chunk_size: u64,
        depth_output: DepthOutput,
    ) -> Result<Self, RecordError> {
        let file = File::create(path)
            .map_err(|e| RecordError::Io { path: path.display().to_string(), source: e })?;
        let (comp, level) = compression.mcap();
        let opts = mcap::WriteOptions::new()
            .compression(comp)
            .compression_level(level)
            .compression_threads(compression_threads)
            .chunk_size(Some(chunk_size))
            .profile("")
            .library(format!("hitl-record {}", env!("CARGO_PKG_VERSION")));
        let mut w = opts.create(BufWriter::with_capacity(1 << 20, file))?;
        let mut ids = [0u16; CHANNELS.len()];
        for (i, ch) in CHANNELS.iter().enumerate() {
            let (name, enc, data) = ch.schema()?;
            let sid = w.add_schema(&name, enc, &data)?;
            let msg_enc = if enc == "protobuf" { "protobuf" } else { "json" };
            ids[i] = w.add_channel(sid, ch.topic(), msg_enc, &BTreeMap::new())?;
        }
        w.write_metadata(&Metadata {
            name: topics::META_RUN.to_string(),
            metadata: meta.to_map(),
        })?;
        if let Some(sun) = &meta.sun_phase {
            let sun = sun.decimated(4096);
            let mut m = BTreeMap::new();
            m.insert("t_s".into(), serde_json::to_string(&sun.t_s)?);
            m.insert("sun_phase_deg".into(), serde_json::to_string(&sun.sun_phase_deg)?);
            w.write_metadata(&Metadata { name: topics::META_SUN_PHASE.to_string(), metadata: m })?;
        }
        w.flush()?;
        Ok(Self {
            w,
            ids,
            seq: [0; CHANNELS.len()],
            written: [0; CHANNELS.len()],
            buf: Vec::with_capacity(4096),
            bytes_in: 0,
            depth_output,
            live: None,
        })
    }

    fn put(&mut self, ch: Ch, log_time: u64, data: &[u8]) -> Result<(), RecordError> {
        let i = ch as usize;
        self.seq[i] = self.seq[i].wrapping_add(1);
        self.w.write_to_known_channel(
            &MessageHeader {
                channel_id: self.ids[i],
                sequence: self.seq[i],
                log_time,
                publish_time: log_time,
            },
            data,
        )?;
        self.written[i] += 1;
        self.bytes_in += data.len() as u64;
        if let Some(live) = &self.live {
            live.offer(ch, log_time, data);
        }
        Ok(())
    }

    fn put_buf(&mut self, ch: Ch, log_time: u64) -> Result<(), RecordError> {
        let buf = std::mem::take(&mut self.buf);
        let r = self.put(ch, log_time, &buf);
        self.buf = buf;
        r
    }

    fn json<T: Serialize>(&mut self, ch: Ch, log_time: u64, m: &T) -> Result<(), RecordError> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, m)?;
        self.put_buf(ch, log_time)
    }

    fn proto<T: Encode>(&mut self, ch: Ch, log_time: u64, m: &T) -> Result<(), RecordError> {
        self.buf.clear();
        m.encode(&mut self.buf).map_err(|e| RecordError::Encode(format!("{}: {e}", ch.topic())))?;
        self.put_buf(ch, log_time)
    }

    pub fn setpoint(&mut self, m: &SetpointMsg) -> Result<(), RecordError> {
        self.json(Ch::Setpoint, m.t_ns, m)
    }
    pub fn state(&mut self, m: &ArmStateMsg) -> Result<(), RecordError> {
        self.json(Ch::State, m.t_ns, m)
    }
    pub fn timing(&mut self, m: &TimingMsg) -> Result<(), RecordError> {
        self.json(Ch::Timing, m.t_ns, m)
    }
    pub fn light(&mut self, m: &LightMsg) -> Result<(), RecordError> {
        self.json(Ch::Light, m.t_ns, m)
    }
    pub fn trigger_fired(&mut self, m: &TriggerFiredMsg) -> Result<(), RecordError> {
        self.json(Ch::TriggerFired, m.t_ns, m)
    }
    pub fn event(&mut self, m: &SafetyEventMsg) -> Result<(), RecordError> {
        let (tick, joint, value, limit) = match &m.detail {
            EventDetail::Numeric { tick, joint, value, limit } => {
                (Some(*tick), *joint, Some(*value), Some(*limit))
            }
            EventDetail::Text(_) => (None, None, None, None),
        };
        let j = EventJson {
            t_ns: m.t_ns,
            kind: m.kind.as_str(),
            detail: m.detail_string(),
            tick,
            joint,
            value: value.filter(|v| v.is_finite()),
            limit: limit.filter(|v| v.is_finite()),
        };
        self.json(Ch::Event, m.t_ns, &j)
    }
    pub fn stats(&mut self, t_ns: u64, v: &serde_json::Value) -> Result<(), RecordError> {
        self.json(Ch::Stats, t_ns, v)
    }

    /// One of the closed loop's `/closed_loop/*` messages.
    pub fn closed_loop(&mut self, m: &crate::msg::ClosedLoopMsg) -> Result<(), RecordError> {
        let ch = match m.topic {
            crate::msg::ClosedLoopTopic::Filter => Ch::ClosedLoopFilter,
            crate::msg::ClosedLoopTopic::Correction => Ch::ClosedLoopCorrection,
            crate::msg::ClosedLoopTopic::Gate => Ch::ClosedLoopGate,
        };
        self.json(ch, m.t_ns, &m.value)
    }

    pub fn tf(&mut self, m: &TfMsg) -> Result<(), RecordError> {
        let t = m.t_ns;
        let msg = fg::FrameTransforms {
            transforms: vec![
                fg_transform(t, topics::FRAME_BASE, topics::FRAME_FLANGE, &m.base_flange),
                fg_transform(t, topics::FRAME_FLANGE, topics::FRAME_CAMERA, &m.flange_camera),
                fg_transform(t, topics::FRAME_BASE, topics::FRAME_TARGET, &m.base_target),
            ],
        };
        self.proto(Ch::Tf, t, &msg)
    }

    fn pose(&mut self, ch: Ch, m: &PoseStamped) -> Result<(), RecordError> {
        let msg = fg::PoseInFrame {
            timestamp: ts(m.capture_ns),
            frame_id: topics::FRAME_CAMERA.to_string(),
            pose: Some(fg_pose(&m.pose)),
        };
        self.proto(ch, m.capture_ns, &msg)
    }
    pub fn pose_estimate(&mut self, m: &PoseStamped) -> Result<(), RecordError> {
        self.pose(Ch::PoseEstimate, m)
    }

    /// Encode a RawImage with its pixels written straight into the message buffer (one copy,
    /// no intermediate byte vector): the small fields first, then the `data` field (tag 6);
    /// protobuf readers accept fields in any order.
    fn image(
        &mut self,
        ch: Ch,
        t: u64,
        (width, height): (u32, u32),
        (encoding, bytes_per_px): (&str, u32),
        pixels: Pixels<'_>,
    ) -> Result<(), RecordError> {
        let msg = fg::RawImage {
            timestamp: ts(t),
            frame_id: topics::FRAME_CAMERA.to_string(),
            width,
            height,
            encoding: encoding.to_string(),
            step: width.saturating_mul(bytes_per_px),
            data: bytes::Bytes::new(),
        };
        self.buf.clear();
        msg.encode(&mut self.buf)
            .map_err(|e| RecordError::Encode(format!("{}: {e}", ch.topic())))?;
        let len = pixels.byte_len();
        self.buf.reserve(len + 11);
        self.buf.push(6 << 3 | 2);
        let mut v = len as u64;
        while v >= 0x80 {
            self.buf.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.buf.push(v as u8);
        pixels.append_le(&mut self.buf);
        self.put_buf(ch, t)
    }

    /// Write every message of one capture, all stamped with its capture time. Returns a
    /// description of what was malformed (and skipped), if anything.
    pub fn frame(&mut self, f: FrameRecord) -> Result<Option<String>, RecordError> {
        let t = f.capture_ns;
        if let Some(live) = &mut self.live {
            live.frame(&f);
        }
        let mut bad = Vec::new();
        self.proto(Ch::Calibration, t, &calibration(&f.intrinsics, t, 1))?;
        if let Some(trigger_ns) = f.trigger_ns {
            let sync = CaptureSyncMsg {
                light_level: f.light_level,
                ..CaptureSyncMsg::new(f.tick, trigger_ns, t)
            };
            self.json(Ch::CaptureSync, t, &sync)?;
        }
        if let Some(tf) = &f.tf {
            let mut tf = *tf;
            tf.t_ns = t;
            self.tf(&tf)?;
        }
        if let Some(p) = &f.gt_pose {
            self.pose(Ch::PoseGt, &PoseStamped { capture_ns: t, pose: *p })?;
        }
        if let Some(c) = f.color {
            if c.is_consistent(3) {
                self.image(Ch::Color, t, (c.width, c.height), ("rgb8", 3), Pixels::U8(&c.data))?;
            } else {
                bad.push("color");
            }
        }
        if let Some(m) = f.mask {
            if m.is_consistent(1) {
                self.image(Ch::Mask, t, (m.width, m.height), ("mono8", 1), Pixels::U8(&m.data))?;
            } else {
                bad.push("mask");
            }
        }
        if let Some(d) = f.depth {
            let ok = match &d {
                DepthImage::Metres(p) => p.is_consistent(1),
                DepthImage::Millimetres(p) => p.is_consistent(1),
            };
            if ok {
                let (dims, fmt, px) = match (&d, self.depth_output) {
                    (DepthImage::Millimetres(p), _) => {
                        ((p.width, p.height), ("16UC1", 2), Pixels::U16(&p.data))
                    }
                    (DepthImage::Metres(p), DepthOutput::Millimetres16) => {
                        ((p.width, p.height), ("16UC1", 2), Pixels::MetresAsMm(&p.data))
                    }
                    (DepthImage::Metres(p), DepthOutput::AsDelivered) => {
                        ((p.width, p.height), ("32FC1", 4), Pixels::F32(&p.data))
                    }
                };
                self.image(Ch::Depth, t, dims, fmt, px)?;
            } else {
                bad.push("depth");
            }
        }
        Ok((!bad.is_empty()).then(|| {
            format!("tick {}: {} buffer size does not match width x height", f.tick, bad.join(", "))
        }))
    }

    /// Close the current chunk and hand it to the OS (survives a kill of this process).
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.w.flush()?;
        Ok(())
    }

    pub fn write_metadata(
        &mut self,
        name: &str,
        map: BTreeMap<String, String>,
    ) -> Result<(), RecordError> {
        self.w.write_metadata(&Metadata { name: name.to_string(), metadata: map })?;
        Ok(())
    }

    /// Write the summary and footer, flush and sync the file.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.w.finish()?;
        let bw = self.w.into_inner();
        let file = bw
            .into_inner()
            .map_err(|e| RecordError::Io { path: "recording".into(), source: e.into_error() })?;
        file.sync_all().map_err(|e| RecordError::Io { path: "recording".into(), source: e })?;
        Ok(())
    }
}

/// Pixels to append little-endian to a message.
enum Pixels<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
    F32(&'a [f32]),
    /// 32FC1 metres written as 16UC1 millimetres.
    MetresAsMm(&'a [f32]),
}

impl Pixels<'_> {
    fn byte_len(&self) -> usize {
        match self {
            Pixels::U8(v) => v.len(),
            Pixels::U16(v) => v.len() * 2,
            Pixels::F32(v) => v.len() * 4,
            Pixels::MetresAsMm(v) => v.len() * 2,
        }
    }

    fn append_le(&self, out: &mut Vec<u8>) {
        fn put<T: Copy, const N: usize>(out: &mut Vec<u8>, v: &[T], f: impl Fn(T) -> [u8; N]) {
            let start = out.len();
            out.resize(start + v.len() * N, 0);
            for (d, x) in out[start..].chunks_exact_mut(N).zip(v) {
                d.copy_from_slice(&f(*x));
            }
        }
        match self {
            Pixels::U8(v) => out.extend_from_slice(v),
            Pixels::U16(v) => put(out, v, u16::to_le_bytes),
            Pixels::F32(v) => put(out, v, f32::to_le_bytes),
            Pixels::MetresAsMm(v) => put(out, v, |m| metres_to_mm(m).to_le_bytes()),
        }
    }
}
