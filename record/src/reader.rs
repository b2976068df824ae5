//! Reading a recording back: walks the file in order and decodes the project's messages, for
//! `hitl report`, `hitl eval`, `hitl calibrate --from-recording` and `hitl export`.
//!
//! A damaged or cut file is read as far as it is sound: chunks are checked against their CRC
//! before any of their messages is handed out, and the walk stops at the first record that is
//! cut, damaged or does not decompress. [`ReadEnd`] says how far it got: the captures read, the
//! captures the file's summary says it holds (when it has a readable summary), and why the walk
//! stopped. A file with neither a readable record nor a readable summary (an empty file, one cut
//! inside its first chunk) is an error, never an empty recording.

use crate::error::ReadError;
use crate::msg::{
    ArmStateMsg, CaptureSyncMsg, LightMsg, PoseStamped, SetpointMsg, TfMsg, TimingMsg,
    TriggerFiredMsg,
};
use crate::topics;
use foxglove::messages as fg;
use hitl_hal::{pose, Distortion, DistortionModel, Intrinsics, Pose};
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use mcap::McapError;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::io::{Read, Seek};
use std::ops::ControlFlow;
use std::path::Path;

/// Largest record the reader accepts (a corrupt length must not allocate without bound).
const RECORD_LIMIT: usize = 1 << 30;

/// How a walk through the file ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ReadEnd {
    /// The walk reached the footer: the whole file was read (closed cleanly, nothing damaged).
    pub complete: bool,
    /// Why reading stopped before the footer (a file cut short by a crash, damaged bytes), if
    /// it did.
    pub truncated: Option<String>,
    /// Captures read: `/camera/calibration` messages (every capture writes one) met before the
    /// walk ended.
    pub frames_read: u64,
    /// Captures the file holds, from its summary's statistics; `None` (unknown) when the file
    /// has no readable summary (a file cut short has none).
    pub frames_recorded: Option<u64>,
}

/// How much of a recording was read: "41 of 41 frames read", "18 of 41 frames read", "18 frames
/// read of an unknown number recorded" (a file without a summary).
pub fn frames_text(read: u64, recorded: Option<u64>) -> String {
    match recorded {
        Some(n) => format!("{read} of {n} frames read"),
        None => format!("{read} frames read of an unknown number recorded"),
    }
}

impl ReadEnd {
    /// [`frames_text`] of this walk.
    pub fn frames_text(&self) -> String {
        frames_text(self.frames_read, self.frames_recorded)
    }

    /// One line for the user when not all of the file was read (`None` when it was): why, and
    /// how much was used.
    pub fn warning(&self, path: &Path) -> Option<String> {
        if self.complete {
            return None;
        }
        Some(format!(
            "{} was not read to its end: {}; {}, only those are used",
            path.display(),
            self.truncated.as_deref().unwrap_or("the reading stopped early"),
            self.frames_text()
        ))
    }
}

/// One message as stored.
pub struct RawMessage<'a> {
    pub topic: &'a str,
    pub log_time: u64,
    pub data: &'a [u8],
}

/// What an MCAP error means to someone reading a recording (the crate's own text for an I/O
/// error speaks of writing).
fn describe(e: &McapError) -> String {
    match e {
        McapError::BadMagic => "it does not start and end with the MCAP magic bytes".into(),
        McapError::BadChunkCrc { .. } => {
            format!("damaged bytes: a chunk's checksum does not match its contents ({e})")
        }
        McapError::Io(io) => format!("damaged bytes: a chunk does not decompress ({io})"),
        McapError::DecompressionError(m) => {
            format!("damaged bytes: a chunk does not decompress ({m})")
        }
        McapError::UnexpectedEof => "the file ends in the middle of a record: cut short".into(),
        McapError::UnexpectedEoc
        | McapError::BadChunkLength { .. }
        | McapError::BadSchemaLength { .. }
        | McapError::RecordTooLarge { .. }
        | McapError::ChunkTooLarge(_)
        | McapError::Parse(_) => {
            format!("damaged bytes: a record's lengths or fields are invalid ({e})")
        }
        McapError::UnsupportedCompression(c) => {
            format!("a chunk uses compression `{c}`, which this reader does not have")
        }
        other => format!("an unreadable record ({other})"),
    }
}

/// The captures the file's summary says it holds: the message count of `/camera/calibration`
/// in its statistics. `None` without a readable summary or statistics.
pub fn frames_recorded(path: &Path) -> Option<u64> {
    let mut file = std::fs::File::open(path).ok()?;
    let size = file.metadata().ok()?.len();
    let mut r = SummaryReader::new_with_options(
        SummaryReaderOptions::default().with_file_size(size).with_record_length_limit(RECORD_LIMIT),
    );
    while let Some(ev) = r.next_event() {
        match ev.ok()? {
            SummaryReadEvent::ReadRequest(n) => {
                let got = file.read(r.insert(n)).ok()?;
                r.notify_read(got);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file.seek(to).ok()?;
                r.notify_seeked(pos);
            }
        }
    }
    let summary = r.finish()?;
    let stats = summary.stats?;
    let counts = &stats.channel_message_counts;
    let n = summary
        .channels
        .iter()
        .filter(|(_, c)| c.topic == topics::CALIBRATION)
        .map(|(id, _)| counts.get(id).copied().unwrap_or(0))
        .sum();
    Some(n)
}

/// What [`visit`]'s walk has seen so far.
#[derive(Default)]
struct Walk {
    /// Topic by channel id.
    channels: HashMap<u16, String>,
    /// A record past the header (a channel, a message, metadata...) was read.
    data_record: bool,
    /// The footer was read.
    complete: bool,
    /// `/calibration` frames read.
    frames_read: u64,
}

impl Walk {
    /// Take one record: messages go to `on_msg`, metadata to `on_meta`. Break when `on_msg`
    /// stops the walk.
    fn take(
        &mut self,
        rec: Record<'_>,
        on_msg: &mut impl FnMut(RawMessage<'_>) -> ControlFlow<()>,
        on_meta: &mut impl FnMut(&str, &BTreeMap<String, String>),
    ) -> ControlFlow<()> {
        match rec {
            Record::Header(_) => {}
            Record::Channel(c) => {
                self.data_record = true;
                self.channels.insert(c.id, c.topic);
            }
            Record::Message { header, data } => {
                self.data_record = true;
                let topic = self.channels.get(&header.channel_id).map(String::as_str).unwrap_or("");
                if topic == topics::CALIBRATION {
                    self.frames_read += 1;
                }
                return on_msg(RawMessage { topic, log_time: header.log_time, data: &data });
            }
            Record::Metadata(m) => {
                self.data_record = true;
                on_meta(&m.name, &m.metadata)
            }
            Record::Footer(_) => self.complete = true,
            _ => self.data_record = true,
        }
        ControlFlow::Continue(())
    }
}

/// Walk every message and metadata record in file order, as far as the file is sound (see the
/// module's documentation). `on_msg` may stop the walk early.
pub fn visit(
    path: &Path,
    mut on_msg: impl FnMut(RawMessage<'_>) -> ControlFlow<()>,
    mut on_meta: impl FnMut(&str, &BTreeMap<String, String>),
) -> Result<ReadEnd, ReadError> {
    let p = path.display().to_string();
    let mut file =
        std::fs::File::open(path).map_err(|e| ReadError::Io { path: p.clone(), source: e })?;
    let mut r = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(RECORD_LIMIT)
            .with_prevalidate_chunk_crcs(true),
    );
    let mut walk = Walk::default();
    let (mut bytes, mut any_record) = (0u64, false);
    // Why the walk stopped before the footer (None: it reached the footer, or the caller
    // stopped it).
    let mut stopped: Option<String> = None;
    while let Some(ev) = r.next_event() {
        let ev = match ev {
            Ok(ev) => ev,
            Err(e) => {
                if !any_record {
                    let reason = if bytes == 0 {
                        "the file is empty (0 bytes)".to_string()
                    } else {
                        describe(&e)
                    };
                    return Err(ReadError::NotMcap { path: p, reason });
                }
                if !walk.complete {
                    stopped = Some(describe(&e));
                }
                break;
            }
        };
        match ev {
            LinearReadEvent::ReadRequest(n) => {
                let buf = r.insert(n);
                let got =
                    file.read(buf).map_err(|e| ReadError::Io { path: p.clone(), source: e })?;
                if got == 0 {
                    if bytes == 0 {
                        return Err(ReadError::NotMcap {
                            path: p,
                            reason: "the file is empty (0 bytes)".into(),
                        });
                    }
                    // End of the file before the footer: a file cut short by a crash.
                    stopped = Some(if any_record {
                        "the file ends before its footer: cut short".into()
                    } else {
                        format!("the file ends after {bytes} bytes, inside its header")
                    });
                    break;
                }
                bytes += got as u64;
                r.notify_read(got);
            }
            LinearReadEvent::Record { data, opcode } => {
                any_record = true;
                let rec = match mcap::parse_record(opcode, data) {
                    Ok(rec) => rec,
                    Err(e) => {
                        stopped = Some(describe(&e));
                        break;
                    }
                };
                if walk.take(rec, &mut on_msg, &mut on_meta).is_break() {
                    return Ok(ReadEnd {
                        complete: false,
                        truncated: None,
                        frames_read: walk.frames_read,
                        frames_recorded: frames_recorded(path),
                    });
                }
            }
        }
    }
    let recorded = frames_recorded(path);
    if !walk.data_record && recorded.is_none() {
        // Nothing but (part of) a header: no chunk, no summary. Not an empty recording.
        return Err(ReadError::Unreadable {
            path: p,
            reason: format!(
                "no readable chunk and no summary in its {bytes} bytes ({}); a recording cut \
                 off as it started, or not a recording",
                stopped.as_deref().unwrap_or("nothing after the header")
            ),
        });
    }
    Ok(ReadEnd {
        complete: walk.complete,
        truncated: if walk.complete {
            None
        } else {
            stopped.or(Some("the file ends before its footer".into()))
        },
        frames_read: walk.frames_read,
        frames_recorded: recorded,
    })
}

/// A `/safety/event` as read back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventRecord {
    pub t_ns: u64,
    pub kind: String,
    pub detail: String,
}

/// An image's header (pixels are not kept).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageInfo {
    pub t_ns: u64,
    pub width: u32,
    pub height: u32,
    pub encoding: String,
}

/// Everything but the pixels of a recording.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// Metadata records by name (`run`, `sun_phase`, `recorder_stats`).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    pub setpoints: Vec<SetpointMsg>,
    pub states: Vec<ArmStateMsg>,
    pub timing: Vec<TimingMsg>,
    pub lights: Vec<LightMsg>,
    /// `/trigger/fired`, in tick order.
    pub trigger_fired: Vec<TriggerFiredMsg>,
    /// `/camera/sync`, one per recorded frame, in trigger order.
    pub capture_sync: Vec<CaptureSyncMsg>,
    pub events: Vec<EventRecord>,
    pub tf: Vec<TfMsg>,
    pub pose_gt: Vec<PoseStamped>,
    pub pose_estimate: Vec<PoseStamped>,
    /// `/recorder/stats` messages, in order.
    pub recorder_stats: Vec<serde_json::Value>,
    /// `/closed_loop/*` messages (topic, log time, message), in file order.
    pub closed_loop: Vec<(String, u64, serde_json::Value)>,
    pub depth_images: Vec<ImageInfo>,
    /// Messages per topic.
    pub topic_counts: BTreeMap<String, u64>,
    pub end: Option<ReadEnd>,
}

impl Recording {
    /// The Sun phase schedule (`t_s`, degrees), when the run recorded one.
    pub fn sun_phase(&self) -> Option<(Vec<f64>, Vec<f64>)> {
        let m = self.metadata.get(topics::META_SUN_PHASE)?;
        let t: Vec<f64> = serde_json::from_str(m.get("t_s")?).ok()?;
        let d: Vec<f64> = serde_json::from_str(m.get("sun_phase_deg")?).ok()?;
        (t.len() == d.len()).then_some((t, d))
    }
}

fn bad(path: &Path, topic: &str, reason: impl ToString) -> ReadError {
    ReadError::BadMessage {
        path: path.display().to_string(),
        topic: topic.to_string(),
        reason: reason.to_string(),
    }
}

/// A recorded position and orientation as a [`Pose`]: a missing position is the origin, a missing
/// orientation no rotation, a quaternion off unit length re-normalised; one that is not finite
/// or of norm (near) zero is refused, as is a non-finite position.
fn pose_of(
    position: Option<fg::Vector3>,
    orientation: Option<fg::Quaternion>,
) -> Result<Pose, String> {
    let t = position.unwrap_or_default();
    let q = orientation.unwrap_or(fg::Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 });
    pose::from_quat_xyzw_t([q.x, q.y, q.z, q.w], [t.x, t.y, t.z]).ok_or_else(|| {
        format!(
            "pose is not a rigid transform: position ({}, {}, {}), quaternion (x, y, z, w) \
             ({}, {}, {}, {})",
            t.x, t.y, t.z, q.x, q.y, q.z, q.w
        )
    })
}

fn ts_ns(t: Option<fg::Timestamp>) -> Option<u64> {
    t.map(|t| t.total_nanos())
}

/// Decode a `/tf` message into the project's transform set (`None` if a frame is missing); a
/// transform that is not rigid (see `pose_of`) is an error.
pub fn decode_tf(data: &[u8], log_time: u64) -> Result<Option<TfMsg>, String> {
    let m = <fg::FrameTransforms as prost::Message>::decode(data).map_err(|e| e.to_string())?;
    let mut tf = TfMsg {
        t_ns: log_time,
        base_flange: Pose::identity(),
        flange_camera: Pose::identity(),
        base_target: Pose::identity(),
    };
    let mut seen = 0u8;
    for t in m.transforms {
        if let Some(ns) = ts_ns(t.timestamp) {
            tf.t_ns = ns;
        }
        let (slot, bit) = match (t.parent_frame_id.as_str(), t.child_frame_id.as_str()) {
            (topics::FRAME_BASE, topics::FRAME_FLANGE) => (&mut tf.base_flange, 1),
            (topics::FRAME_FLANGE, topics::FRAME_CAMERA) => (&mut tf.flange_camera, 2),
            (topics::FRAME_BASE, topics::FRAME_TARGET) => (&mut tf.base_target, 4),
            _ => continue,
        };
        *slot = pose_of(t.translation, t.rotation)
            .map_err(|e| format!("{} -> {}: {e}", t.parent_frame_id, t.child_frame_id))?;
        seen |= bit;
    }
    Ok((seen == 7).then_some(tf))
}

/// Decode a `/pose/gt` or `/pose/estimate` message (a pose that is not rigid is an error).
pub fn decode_pose(data: &[u8], log_time: u64) -> Result<PoseStamped, String> {
    let m = <fg::PoseInFrame as prost::Message>::decode(data).map_err(|e| e.to_string())?;
    let p = m.pose.unwrap_or_default();
    let pose = pose_of(p.position, p.orientation)?;
    Ok(PoseStamped { capture_ns: ts_ns(m.timestamp).unwrap_or(log_time), pose })
}

/// Why a `/camera/calibration` message gives no intrinsics.
#[derive(Debug)]
pub enum CalibrationError {
    /// Not a `foxglove.CameraCalibration`.
    Undecodable(prost::DecodeError),
    /// Decoded, but its K matrix is not 9 finite numbers with positive focal lengths, or its
    /// image size is zero.
    NoUsableK,
    /// Nonzero `D` of a model not known (its name), or of the wrong count for its model.
    UnknownDistortion(String, usize),
}

impl std::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Undecodable(e) => write!(f, "undecodable /camera/calibration: {e}"),
            Self::NoUsableK => f.write_str("a /camera/calibration has no usable K matrix"),
            Self::UnknownDistortion(model, n) => write!(
                f,
                "a /camera/calibration's distortion is {n} coefficients of model {model:?} (known: \
                 plumb_bob with 5, rational_polynomial with 8, all finite)"
            ),
        }
    }
}

/// Decode a `/camera/calibration` message into the camera's intrinsics and their time (the
/// message's timestamp, else `log_time`): the inverse of what the recorder writes.
pub fn decode_intrinsics(
    data: &[u8],
    log_time: u64,
) -> Result<(u64, Intrinsics), CalibrationError> {
    let c = <fg::CameraCalibration as prost::Message>::decode(data)
        .map_err(CalibrationError::Undecodable)?;
    let usable = c.k.len() == 9
        && c.k.iter().all(|v| v.is_finite())
        && c.k[0] > 0.0
        && c.k[4] > 0.0
        && c.width > 0
        && c.height > 0;
    if !usable {
        return Err(CalibrationError::NoUsableK);
    }
    // The lens: `D` in its model's count; a recording written before lenses were recorded (all
    // zeros), or without `D`, is a pinhole.
    let distortion = if c.d.iter().all(|v| *v == 0.0) {
        Distortion::NONE
    } else {
        DistortionModel::from_name(&c.distortion_model)
            .and_then(|m| Distortion::from_d(m, &c.d))
            .ok_or(CalibrationError::UnknownDistortion(c.distortion_model.clone(), c.d.len()))?
    };
    let k = Intrinsics {
        width: c.width,
        height: c.height,
        fx: c.k[0],
        fy: c.k[4],
        cx: c.k[2],
        cy: c.k[5],
        distortion,
    };
    Ok((ts_ns(c.timestamp).unwrap_or(log_time), k))
}

/// Decode a `/camera/*` image.
pub fn decode_image(data: &[u8]) -> Result<fg::RawImage, prost::DecodeError> {
    <fg::RawImage as prost::Message>::decode(data)
}

/// The image's rows without their padding, `bpp` bytes per pixel (a `step` of 0 means rows
/// without padding); `None` when the step is shorter than a row or the buffer than the image.
pub fn packed_rows(img: &fg::RawImage, bpp: usize) -> Option<Vec<u8>> {
    let (w, h) = (img.width as usize, img.height as usize);
    let row = w.checked_mul(bpp)?;
    let step = if img.step == 0 { row } else { img.step as usize };
    if step < row || img.data.len() < step.checked_mul(h)? {
        return None;
    }
    let mut out = Vec::with_capacity(row * h);
    for r in 0..h {
        out.extend_from_slice(&img.data[r * step..r * step + row]);
    }
    Some(out)
}

/// Depth in metres from a 32FC1 (metres) or 16UC1 (millimetres) image; `None` for other
/// encodings or a buffer that does not match the size.
pub fn depth_metres(img: &fg::RawImage) -> Option<Vec<f32>> {
    let (w, h) = (img.width as usize, img.height as usize);
    let (bpp, step) = match img.encoding.as_str() {
        "32FC1" => (4, img.step as usize),
        "16UC1" => (2, img.step as usize),
        _ => return None,
    };
    if step < w * bpp || img.data.len() < step * h {
        return None;
    }
    let mut out = Vec::with_capacity(w * h);
    for row in 0..h {
        let r = &img.data[row * step..row * step + w * bpp];
        if bpp == 4 {
            out.extend(r.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])));
        } else {
            out.extend(
                r.chunks_exact(2).map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) / 1000.0),
            );
        }
    }
    Some(out)
}

/// Read a recording's messages (all but pixels), sorted by time within each topic.
pub fn read_recording(path: &Path) -> Result<Recording, ReadError> {
    let mut rec = Recording::default();
    let mut err: Option<ReadError> = None;
    let mut metas = Vec::new();
    let end = visit(
        path,
        |m| {
            *rec.topic_counts.entry(m.topic.to_string()).or_insert(0) += 1;
            if let Err(e) = decode_into(&mut rec, &m) {
                err = Some(bad(path, m.topic, e));
                return ControlFlow::Break(());
            }
            ControlFlow::Continue(())
        },
        |name, map| metas.push((name.to_string(), map.clone())),
    )?;
    if let Some(e) = err {
        return Err(e);
    }
    rec.metadata.extend(metas);
    rec.setpoints.sort_by_key(|m| m.t_ns);
    rec.states.sort_by_key(|m| m.t_ns);
    rec.timing.sort_by_key(|m| m.t_ns);
    rec.lights.sort_by_key(|m| m.t_ns);
    rec.trigger_fired.sort_by_key(|m| m.tick);
    rec.capture_sync.sort_by_key(|m| m.trigger_ns);
    rec.events.sort_by_key(|m| m.t_ns);
    rec.tf.sort_by_key(|m| m.t_ns);
    rec.pose_gt.sort_by_key(|m| m.capture_ns);
    rec.pose_estimate.sort_by_key(|m| m.capture_ns);
    rec.end = Some(end);
    Ok(rec)
}

fn decode_into(rec: &mut Recording, m: &RawMessage<'_>) -> Result<(), String> {
    let e = |x: &dyn std::fmt::Display| x.to_string();
    match m.topic {
        topics::SETPOINT => rec.setpoints.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?),
        topics::STATE => rec.states.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?),
        topics::TIMING => rec.timing.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?),
        topics::LIGHT => rec.lights.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?),
        topics::TRIGGER_FIRED => {
            rec.trigger_fired.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?)
        }
        topics::CAPTURE_SYNC => {
            rec.capture_sync.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?)
        }
        topics::EVENT => rec.events.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?),
        topics::RECORDER_STATS => {
            rec.recorder_stats.push(serde_json::from_slice(m.data).map_err(|x| e(&x))?)
        }
        topics::CLOSED_LOOP_FILTER | topics::CLOSED_LOOP_CORRECTION | topics::CLOSED_LOOP_GATE => {
            let v = serde_json::from_slice(m.data).map_err(|x| e(&x))?;
            rec.closed_loop.push((m.topic.to_string(), m.log_time, v));
        }
        topics::TF => {
            if let Some(tf) = decode_tf(m.data, m.log_time)? {
                rec.tf.push(tf);
            }
        }
        topics::POSE_GT => rec.pose_gt.push(decode_pose(m.data, m.log_time)?),
        topics::POSE_ESTIMATE => rec.pose_estimate.push(decode_pose(m.data, m.log_time)?),
        topics::DEPTH => {
            let img = decode_image(m.data).map_err(|x| e(&x))?;
            rec.depth_images.push(ImageInfo {
                t_ns: ts_ns(img.timestamp).unwrap_or(m.log_time),
                width: img.width,
                height: img.height,
                encoding: img.encoding,
            });
        }
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;

    #[test]
    fn packed_rows_drop_the_padding_and_refuse_short_buffers() {
        let img = |step: u32, data: Vec<u8>| fg::RawImage {
            width: 2,
            height: 2,
            encoding: "mono8".into(),
            step,
            data: data.into(),
            ..Default::default()
        };
        assert_eq!(packed_rows(&img(3, vec![1, 2, 9, 3, 4, 9]), 1), Some(vec![1, 2, 3, 4]));
        assert_eq!(packed_rows(&img(0, vec![1, 2, 3, 4]), 1), Some(vec![1, 2, 3, 4]));
        assert_eq!(packed_rows(&img(3, vec![1, 2, 9, 3, 4]), 1), None, "buffer short");
        assert_eq!(packed_rows(&img(1, vec![1, 2, 3, 4]), 1), None, "step shorter than a row");
    }

    #[test]
    fn intrinsics_are_what_the_recorder_wrote_and_bad_ones_are_named() {
        let k = Intrinsics::pinhole(640, 400, 500.0, 501.0, 320.5, 199.5);
        let data = crate::channels::calibration(&k, 7, 1).encode_to_vec();
        let (t, back) = decode_intrinsics(&data, 99).expect("decodes");
        assert_eq!((t, back), (7, k));
        // The lens's five numbers and its model come back as written.
        let lens = k.with_distortion(Distortion::brown_conrady([-0.1, 0.02, 1e-3, -2e-3, 0.004]));
        let msg = crate::channels::calibration(&lens, 7, 1);
        assert_eq!(msg.distortion_model, "plumb_bob");
        assert_eq!(msg.d, vec![-0.1, 0.02, 1e-3, -2e-3, 0.004]);
        let (_, back) = decode_intrinsics(&msg.encode_to_vec(), 99).expect("decodes");
        assert_eq!(back, lens);
        let odd = fg::CameraCalibration { distortion_model: "equidistant".into(), ..msg };
        assert!(matches!(
            decode_intrinsics(&odd.encode_to_vec(), 99),
            Err(CalibrationError::UnknownDistortion(m, 5)) if m == "equidistant"
        ));
        let zero_fx = Intrinsics { fx: 0.0, ..k };
        let data = crate::channels::calibration(&zero_fx, 7, 1).encode_to_vec();
        assert!(matches!(decode_intrinsics(&data, 99), Err(CalibrationError::NoUsableK)));
        assert!(matches!(decode_intrinsics(&[0xff; 3], 0), Err(CalibrationError::Undecodable(_))));
    }

    fn pose_msg(orientation: Option<fg::Quaternion>) -> Vec<u8> {
        fg::PoseInFrame {
            timestamp: None,
            frame_id: topics::FRAME_CAMERA.into(),
            pose: Some(fg::Pose {
                position: Some(fg::Vector3 { x: 0.1, y: 0.2, z: 1.0 }),
                orientation,
            }),
        }
        .encode_to_vec()
    }

    fn q(x: f64, y: f64, z: f64, w: f64) -> Option<fg::Quaternion> {
        Some(fg::Quaternion { x, y, z, w })
    }

    #[test]
    fn recorded_quaternions_are_renormalised_or_refused() {
        // Twice unit length, 90 degrees about z: re-normalised.
        let h = std::f64::consts::FRAC_PI_4;
        let p = decode_pose(&pose_msg(q(0.0, 0.0, 2.0 * h.sin(), 2.0 * h.cos())), 5).expect("ok");
        assert_eq!(p.capture_ns, 5);
        assert!((p.pose.rotation.angle() - 2.0 * h).abs() < 1e-12);
        assert!((p.pose.rotation.coords.norm() - 1.0).abs() < 1e-15);
        assert_eq!(p.pose.translation.vector, nalgebra::Vector3::new(0.1, 0.2, 1.0));
        // No orientation: no rotation.
        assert_eq!(decode_pose(&pose_msg(None), 5).expect("ok").pose.rotation.angle(), 0.0);
        // Zero length or not finite: refused, with the numbers.
        for bad in [q(0.0, 0.0, 0.0, 0.0), q(f64::NAN, 0.0, 0.0, 1.0)] {
            let e = decode_pose(&pose_msg(bad), 5).expect_err("refused");
            assert!(e.contains("not a rigid transform"), "{e}");
        }
    }

    #[test]
    fn a_bad_transform_is_refused_only_where_it_is_used() {
        let tf = |parent: &str, child: &str, rotation| fg::FrameTransform {
            timestamp: None,
            parent_frame_id: parent.into(),
            child_frame_id: child.into(),
            translation: Some(fg::Vector3 { x: 0.0, y: 0.0, z: 0.5 }),
            rotation,
        };
        let ok = q(0.0, 0.0, 0.0, 1.0);
        let msg = |flange_rotation, other_rotation| {
            fg::FrameTransforms {
                transforms: vec![
                    tf(topics::FRAME_BASE, topics::FRAME_FLANGE, flange_rotation),
                    tf(topics::FRAME_FLANGE, topics::FRAME_CAMERA, ok),
                    tf(topics::FRAME_BASE, topics::FRAME_TARGET, ok),
                    tf("base", "somewhere_else", other_rotation),
                ],
            }
            .encode_to_vec()
        };
        let zero = q(0.0, 0.0, 0.0, 0.0);
        let t = decode_tf(&msg(ok, zero), 9).expect("the unknown frame is not read").expect("all");
        assert_eq!(t.base_flange.translation.z, 0.5);
        let e = decode_tf(&msg(zero, ok), 9).expect_err("base -> flange is refused");
        assert!(e.contains("base -> flange"), "{e}");
    }
}
