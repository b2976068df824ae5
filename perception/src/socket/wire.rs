//! The bytes of protocol `hitl-pose` version 1 (docs/perception.md, "External estimator over a
//! socket"): encoding the client's messages and decoding and checking the peer's replies. No I/O
//! here; [`super`] moves the bytes.
//!
//! Every message is a `u32` little-endian header length, that many bytes of a UTF-8 JSON object
//! (the header), then the binary payloads the header's `payloads` list announces, in that order,
//! each exactly `bytes` long. The peer's replies carry no payloads in version 1.

use crate::estimator::{Estimate, EstimateKind};
use crate::models::Mesh;
use crate::PerceptionFrame;
use hitl_hal::pose;
use nalgebra::Matrix4;
use serde::Deserialize;
use serde_json::{json, Map, Value};

/// Protocol name, sent and expected in `hello`.
pub const PROTOCOL: &str = "hitl-pose";
/// Protocol version, sent and expected in `hello`.
pub const VERSION: u64 = 1;
/// Largest reply header the client reads; a longer announced length is refused before anything
/// is allocated.
pub const MAX_REPLY_HEADER_BYTES: usize = 1 << 20;

/// One binary payload of an outgoing message: little-endian numbers in row-major order.
struct Payload<'a> {
    name: &'static str,
    shape: Vec<usize>,
    data: Data<'a>,
}

enum Data<'a> {
    F64(&'a [f64]),
    F32(&'a [f32]),
    U32(&'a [u32]),
    U8(&'a [u8]),
}

impl Data<'_> {
    /// numpy's name for the element type (`np.dtype(...)` understands it).
    fn dtype(&self) -> &'static str {
        match self {
            Data::F64(_) => "<f8",
            Data::F32(_) => "<f4",
            Data::U32(_) => "<u4",
            Data::U8(_) => "u1",
        }
    }

    fn elements(&self) -> usize {
        match self {
            Data::F64(v) => v.len(),
            Data::F32(v) => v.len(),
            Data::U32(v) => v.len(),
            Data::U8(v) => v.len(),
        }
    }

    fn byte_len(&self) -> usize {
        let size = match self {
            Data::F64(_) => 8,
            Data::F32(_) | Data::U32(_) => 4,
            Data::U8(_) => 1,
        };
        self.elements() * size
    }

    fn write_le(&self, out: &mut Vec<u8>) {
        match self {
            Data::F64(v) => v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Data::F32(v) => v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Data::U32(v) => v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Data::U8(v) => out.extend_from_slice(v),
        }
    }
}

/// Appends one message (length, header, payloads) to `out`. `header` must be a JSON object; its
/// `payloads` list is filled in here from `payloads`.
fn encode(out: &mut Vec<u8>, mut header: Map<String, Value>, payloads: &[Payload]) {
    let list: Vec<Value> = payloads
        .iter()
        .map(|p| {
            debug_assert_eq!(p.shape.iter().product::<usize>(), p.data.elements());
            json!({
                "name": p.name,
                "dtype": p.data.dtype(),
                "shape": p.shape,
                "bytes": p.data.byte_len(),
            })
        })
        .collect();
    header.insert("payloads".into(), Value::Array(list));
    let text = Value::Object(header).to_string();
    let total = text.len() + payloads.iter().map(|p| p.data.byte_len()).sum::<usize>();
    out.reserve(4 + total);
    // A header is a few hundred bytes: far below u32::MAX.
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    for p in payloads {
        p.data.write_le(out);
    }
}

fn object(v: Value) -> Map<String, Value> {
    match v {
        Value::Object(m) => m,
        _ => Map::new(),
    }
}

/// `hello`: protocol, version, client, and the target mesh inline (body frame, metres as the
/// camera sees the target): `vertices` `<f8` [V,3] and `triangles` `<u4` [F,3].
pub(crate) fn encode_hello(out: &mut Vec<u8>, mesh: &Mesh) {
    let header = object(json!({
        "type": "hello",
        "protocol": PROTOCOL,
        "version": VERSION,
        "client": concat!("hitl-perception ", env!("CARGO_PKG_VERSION")),
    }));
    let (v, f) = (mesh.vertices(), mesh.faces());
    let payloads = [
        Payload { name: "vertices", shape: vec![v.len(), 3], data: Data::F64(v.as_flattened()) },
        Payload { name: "triangles", shape: vec![f.len(), 3], data: Data::U32(f.as_flattened()) },
    ];
    encode(out, header, &payloads);
}

/// `frame`: seq, timestamp, intrinsics; payloads `depth` `<f4` [H,W] metres, then `color` u1
/// [H,W,3] if the frame has colour, then `mask` u1 [H,W] if it has a mask. The frame must have
/// passed [`PerceptionFrame::validate`].
pub(crate) fn encode_frame(out: &mut Vec<u8>, frame: &PerceptionFrame) {
    let k = &frame.intrinsics;
    let header = object(json!({
        "type": "frame",
        "seq": frame.seq,
        "timestamp_ns": frame.timestamp_ns,
        "intrinsics": {
            "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
            "width": k.width, "height": k.height,
        },
    }));
    let (h, w) = (k.height as usize, k.width as usize);
    let mut payloads =
        vec![Payload { name: "depth", shape: vec![h, w], data: Data::F32(&frame.depth_m) }];
    if !frame.color.is_empty() {
        payloads.push(Payload {
            name: "color",
            shape: vec![h, w, 3],
            data: Data::U8(&frame.color),
        });
    }
    if let Some(m) = &frame.mask {
        payloads.push(Payload { name: "mask", shape: vec![h, w], data: Data::U8(m) });
    }
    encode(out, header, &payloads);
}

/// `reset`: no fields.
pub(crate) fn encode_reset(out: &mut Vec<u8>) {
    encode(out, object(json!({ "type": "reset" })), &[]);
}

/// A decoded, field-checked reply.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Reply {
    Hello(HelloReply),
    Pose(PoseReply),
    Reset,
    /// The peer could not do what was asked; the connection stays in step.
    Error(String),
}

impl Reply {
    pub(crate) fn type_name(&self) -> &'static str {
        match self {
            Reply::Hello(_) => "hello",
            Reply::Pose(_) => "pose",
            Reply::Reset => "reset",
            Reply::Error(_) => "error",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct HelloReply {
    pub protocol: String,
    pub version: u64,
    pub accept: bool,
    #[serde(default)]
    pub estimator: Option<String>,
    #[serde(default)]
    pub reason: Option<String>,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PoseReply {
    pub seq: u64,
    /// Required, `null` for lost.
    #[serde(deserialize_with = "required_nullable")]
    pub pose: Option<Vec<f64>>,
    #[serde(default)]
    pub kind: Option<String>,
    #[serde(default)]
    pub residual_m: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ErrorReply {
    reason: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Empty {}

/// A field that must be present but may be `null` (serde treats a missing `Option` as `None`
/// unless the field has its own deserializer).
fn required_nullable<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Vec<f64>>, D::Error> {
    Option::<Vec<f64>>::deserialize(d)
}

/// Decodes a reply header. The message is whatever the peer sent: every problem is an `Err`
/// naming it, never a panic.
pub(crate) fn decode_reply(header: &[u8]) -> Result<Reply, String> {
    let text = std::str::from_utf8(header).map_err(|e| format!("header is not UTF-8 ({e})"))?;
    let value: Value = serde_json::from_str(text).map_err(|e| {
        let hint = if ["NaN", "Infinity"].iter().any(|w| text.contains(w)) {
            " (JSON has no NaN or Infinity: a pose must be finite, or null for lost)"
        } else {
            ""
        };
        format!("header is not JSON: {e}{hint}: {}", excerpt(text))
    })?;
    let Value::Object(mut map) = value else {
        return Err(format!("header is not a JSON object: {}", excerpt(text)));
    };
    let kind = match map.remove("type") {
        Some(Value::String(s)) => s,
        Some(_) => return Err("header field `type` is not a string".into()),
        None => return Err(format!("header has no field `type`: {}", excerpt(text))),
    };
    match map.remove("payloads") {
        None => {}
        Some(Value::Array(a)) if a.is_empty() => {}
        Some(_) => {
            return Err(format!(
                "the `{kind}` reply announces payloads; replies carry none in version {VERSION}"
            ))
        }
    }
    let fields = Value::Object(map);
    let bad = |e: serde_json::Error| format!("malformed `{kind}` reply: {e}");
    match kind.as_str() {
        "hello" => Ok(Reply::Hello(HelloReply::deserialize(fields).map_err(bad)?)),
        "pose" => Ok(Reply::Pose(PoseReply::deserialize(fields).map_err(bad)?)),
        "reset" => {
            Empty::deserialize(fields).map_err(bad)?;
            Ok(Reply::Reset)
        }
        "error" => Ok(Reply::Error(ErrorReply::deserialize(fields).map_err(bad)?.reason)),
        other => {
            Err(format!("unknown reply type {other:?} (expected hello, pose, reset or error)"))
        }
    }
}

/// The start of a peer's text, for error messages (never the whole of a 1 MiB header).
fn excerpt(text: &str) -> String {
    const N: usize = 80;
    match text.char_indices().nth(N) {
        Some((i, _)) => format!("{:?}...", &text[..i]),
        None => format!("{text:?}"),
    }
}

/// Turns a checked `pose` reply into an estimate. A finite pose that is not rigid is `Lost`
/// (as for the ONNX backend); a malformed one is an `Err`.
pub(crate) fn estimate_from(reply: &PoseReply) -> Result<Estimate, String> {
    let kind = match reply.kind.as_deref() {
        None => None,
        Some("registered") => Some(EstimateKind::Registered),
        Some("tracked") => Some(EstimateKind::Tracked),
        Some("direct") => Some(EstimateKind::Direct),
        Some("lost") => Some(EstimateKind::Lost),
        Some(k) => {
            return Err(format!(
                "unknown kind {k:?} (expected registered, tracked, direct or lost)"
            ))
        }
    };
    if let Some(r) = reply.residual_m {
        if !(r.is_finite() && r >= 0.0) {
            return Err(format!("residual_m {r} is not a finite number >= 0"));
        }
    }
    let Some(values) = &reply.pose else {
        return match kind {
            None | Some(EstimateKind::Lost) => Ok(Estimate::lost()),
            Some(k) => Err(format!("pose is null (lost) but kind is {k:?}")),
        };
    };
    if kind == Some(EstimateKind::Lost) {
        return Err("kind is \"lost\" but a pose is given".into());
    }
    if values.len() != 16 {
        return Err(format!(
            "pose has {} numbers, expected 16 (row-major 4x4 camera_T_target)",
            values.len()
        ));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(format!("pose element {i} is not finite"));
    }
    let Some(p) = pose::from_matrix_checked(&Matrix4::from_row_slice(values)) else {
        return Ok(Estimate::lost());
    };
    Ok(Estimate {
        pose: Some(p),
        kind: kind.unwrap_or(EstimateKind::Direct),
        residual_m: reply.residual_m.unwrap_or(0.0),
    })
}
