//! The file's channels: each topic, its schema, and the Foxglove encodings the file and the live
//! view share (timestamps, the camera calibration).

use crate::error::RecordError;
use crate::topics;
use foxglove::messages as fg;
use foxglove::Encode;
use hitl_hal::Intrinsics;

/// Every channel of the file, in a fixed order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Ch {
    Setpoint,
    State,
    Timing,
    Light,
    Event,
    Tf,
    PoseGt,
    PoseEstimate,
    Color,
    Depth,
    Mask,
    Calibration,
    CaptureSync,
    TriggerFired,
    Stats,
    ClosedLoopFilter,
    ClosedLoopCorrection,
    ClosedLoopGate,
}

pub(crate) const CHANNELS: [Ch; 18] = [
    Ch::Setpoint,
    Ch::State,
    Ch::Timing,
    Ch::Light,
    Ch::Event,
    Ch::Tf,
    Ch::PoseGt,
    Ch::PoseEstimate,
    Ch::Color,
    Ch::Depth,
    Ch::Mask,
    Ch::Calibration,
    Ch::CaptureSync,
    Ch::TriggerFired,
    Ch::Stats,
    Ch::ClosedLoopFilter,
    Ch::ClosedLoopCorrection,
    Ch::ClosedLoopGate,
];

impl Ch {
    pub(crate) fn topic(self) -> &'static str {
        match self {
            Ch::Setpoint => topics::SETPOINT,
            Ch::State => topics::STATE,
            Ch::Timing => topics::TIMING,
            Ch::Light => topics::LIGHT,
            Ch::Event => topics::EVENT,
            Ch::Tf => topics::TF,
            Ch::PoseGt => topics::POSE_GT,
            Ch::PoseEstimate => topics::POSE_ESTIMATE,
            Ch::Color => topics::COLOR,
            Ch::Depth => topics::DEPTH,
            Ch::Mask => topics::MASK,
            Ch::Calibration => topics::CALIBRATION,
            Ch::CaptureSync => topics::CAPTURE_SYNC,
            Ch::TriggerFired => topics::TRIGGER_FIRED,
            Ch::Stats => topics::RECORDER_STATS,
            Ch::ClosedLoopFilter => topics::CLOSED_LOOP_FILTER,
            Ch::ClosedLoopCorrection => topics::CLOSED_LOOP_CORRECTION,
            Ch::ClosedLoopGate => topics::CLOSED_LOOP_GATE,
        }
    }

    pub(crate) fn schema(self) -> Result<(String, &'static str, Vec<u8>), RecordError> {
        fn fox<T: Encode>() -> Result<(String, &'static str, Vec<u8>), RecordError> {
            let s = T::get_schema()
                .ok_or_else(|| RecordError::Encode("foxglove schema missing".into()))?;
            Ok((s.name, "protobuf", s.data.into_owned()))
        }
        match self {
            Ch::Tf => fox::<fg::FrameTransforms>(),
            Ch::PoseGt | Ch::PoseEstimate => fox::<fg::PoseInFrame>(),
            Ch::Color | Ch::Depth | Ch::Mask => fox::<fg::RawImage>(),
            Ch::Calibration => fox::<fg::CameraCalibration>(),
            _ => {
                let (name, s) = topics::json_schema(self.topic()).ok_or_else(|| {
                    RecordError::Encode(format!("no schema for {}", self.topic()))
                })?;
                Ok((name.to_string(), "jsonschema", s.into_bytes()))
            }
        }
    }
}

pub(crate) fn ts(ns: u64) -> Option<fg::Timestamp> {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Some(fg::Timestamp::new(sec, (ns % 1_000_000_000) as u32))
}

/// The calibration of a registered stream (its lens's distortion `D` and model, R = I) at time
/// `t`, for its image shrunk by a whole `factor` (1: as captured; pixel centres map as
/// (c + 0.5) / factor - 0.5, [`Intrinsics::scaled`]'s convention; the distortion acts on
/// normalised coordinates and is the same at every size).
pub(crate) fn calibration(i: &Intrinsics, t: u64, factor: u32) -> fg::CameraCalibration {
    let s = f64::from(factor.max(1));
    let (fx, fy) = (i.fx / s, i.fy / s);
    let (cx, cy) = ((i.cx + 0.5) / s - 0.5, (i.cy + 0.5) / s - 0.5);
    fg::CameraCalibration {
        timestamp: ts(t),
        frame_id: topics::FRAME_CAMERA.to_string(),
        width: i.width / factor.max(1),
        height: i.height / factor.max(1),
        distortion_model: i.distortion.model.name().to_string(),
        d: i.distortion.d().to_vec(),
        k: vec![fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    }
}
