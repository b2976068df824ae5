//! One recording read back as one episode: a frame for every capture whose images were all
//! recorded, with what the run knew at that instant (joints at exposure, the tick's setpoint,
//! camera pose, ground truth, estimate, intrinsics), and the run's orbit metadata.
//!
//! Reads the recording with `hitl_record::reader` (a file cut short by a crash or damaged is read
//! as far as it is sound, and the episode says how much that was); the pixels are read later,
//! frame by frame, by [`crate::export::video`].

use super::ExportError;
use hitl_hal::{Intrinsics, Pose, DOF};
use hitl_record::reader::{self, CalibrationError, Recording};
use hitl_record::topics;
use std::collections::{BTreeMap, BTreeSet};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// The image streams a frame can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Stream {
    Color,
    Depth,
    Mask,
}

impl Stream {
    pub const ALL: [Stream; 3] = [Stream::Color, Stream::Depth, Stream::Mask];

    /// The recording's topic.
    pub fn topic(self) -> &'static str {
        match self {
            Stream::Color => topics::COLOR,
            Stream::Depth => topics::DEPTH,
            Stream::Mask => topics::MASK,
        }
    }

    fn of_topic(topic: &str) -> Option<Stream> {
        Stream::ALL.into_iter().find(|s| s.topic() == topic)
    }

    /// The encodings the export reads.
    fn accepts(self, encoding: &str) -> bool {
        match self {
            Stream::Color => matches!(encoding, "rgb8" | "bgr8"),
            Stream::Depth => matches!(encoding, "32FC1" | "16UC1"),
            Stream::Mask => encoding == "mono8",
        }
    }
}

/// One recorded capture.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Capture (exposure) time, host monotonic ns: the stamp of every message of the capture.
    pub capture_ns: u64,
    /// The tick that fired the trigger, when the recording says.
    pub tick: Option<u64>,
    /// Measured joints nearest the exposure (`/arm/state`), radians.
    pub state_q: [f64; DOF],
    /// Commanded joints of the capture's tick (`/arm/setpoint`), radians.
    pub action_q: [f64; DOF],
    /// `base_T_camera` (OpenCV camera axes), from the capture's `/tf`.
    pub camera_pose: Option<Pose>,
    /// `camera_T_target`, ground truth.
    pub target_gt: Option<Pose>,
    /// `camera_T_target`, the pose estimator's answer for this frame.
    pub target_estimate: Option<Pose>,
    /// fx, fy, cx, cy in pixels (`/camera/calibration`).
    pub intrinsics: Option<[f64; 4]>,
    /// The lens's distortion, OpenCV's order `k1, k2, p1, p2, k3, k4, k5, k6` (zeros: a pinhole;
    /// the last three zero for the five-coefficient model), from the same message.
    pub distortion: Option<[f64; 8]>,
}

/// What the recording's metadata says about the run (null where it does not say).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EpisodeMeta {
    /// The recording's file name.
    pub recording: String,
    /// The whole file was read (false: cut short or damaged, read as far as it is sound).
    pub complete: bool,
    /// Captures read from the file.
    pub frames_read: u64,
    /// Captures the file holds (its summary); null: unknown (no summary, a file cut short).
    pub frames_recorded: Option<u64>,
    /// Why reading stopped before the end of the file.
    pub read_stopped: Option<String>,
    pub trajectory_sha256: Option<String>,
    /// The trajectory's `meta` as recorded: for `hitl plan` trajectories, the orbital elements,
    /// ROE, scale, time scale and every other input of the plan (docs/planner.md).
    pub orbit: serde_json::Value,
    /// Lab metres per real metre.
    pub scale: Option<f64>,
    /// `--camera-preset` of the run.
    pub camera_preset: Option<String>,
    /// `--camera` of the run (sim, orbbec, ...).
    pub camera: Option<String>,
    /// `--target-model` of the run.
    pub target_model: Option<String>,
    /// Greatest dimension of the target model, real metres.
    pub target_size_m: Option<f64>,
    /// The same in the lab (times `scale`).
    pub target_size_lab_m: Option<f64>,
    /// Image width and height, pixels.
    pub image_size: [u32; 2],
    /// Intrinsics of the first frame: fx, fy, cx, cy.
    pub intrinsics: Option<[f64; 4]>,
    /// The first frame's lens distortion model (`plumb_bob`, `rational_polynomial`).
    pub distortion_model: Option<String>,
    /// Its coefficients, `k1, k2, p1, p2, k3, k4, k5, k6`.
    pub distortion: Option<[f64; 8]>,
    /// Captures left out because one of their images was not recorded.
    pub incomplete_captures: usize,
}

/// One recording as an episode.
#[derive(Debug, Clone)]
pub struct Episode {
    pub path: PathBuf,
    pub frames: Vec<Frame>,
    /// The image streams the recording has (colour always).
    pub streams: BTreeSet<Stream>,
    pub width: u32,
    pub height: u32,
    pub meta: EpisodeMeta,
}

impl Episode {
    /// Median interval between captures, ns (None with fewer than two frames).
    pub fn median_interval_ns(&self) -> Option<u64> {
        let mut d: Vec<u64> =
            self.frames.windows(2).map(|w| w[1].capture_ns - w[0].capture_ns).collect();
        if d.is_empty() {
            return None;
        }
        d.sort_unstable();
        Some(d[d.len() / 2])
    }
}

/// Image headers of one recording: capture times per stream, sizes, encodings, intrinsics.
#[derive(Default)]
struct ImageIndex {
    times: BTreeMap<Stream, BTreeSet<u64>>,
    sizes: BTreeSet<(u32, u32)>,
    bad_encoding: Option<(Stream, String)>,
    intrinsics: BTreeMap<u64, Intrinsics>,
    undecodable: Option<(String, String)>,
}

fn index_images(path: &Path) -> Result<ImageIndex, ExportError> {
    let mut ix = ImageIndex::default();
    reader::visit(
        path,
        |m| {
            if let Some(s) = Stream::of_topic(m.topic) {
                match reader::decode_image(m.data) {
                    Ok(img) => {
                        if !s.accepts(&img.encoding) {
                            ix.bad_encoding = Some((s, img.encoding.clone()));
                            return ControlFlow::Break(());
                        }
                        let t = img.timestamp.map(|t| t.total_nanos()).unwrap_or(m.log_time);
                        ix.times.entry(s).or_default().insert(t);
                        ix.sizes.insert((img.width, img.height));
                    }
                    Err(e) => {
                        ix.undecodable = Some((m.topic.to_string(), e.to_string()));
                        return ControlFlow::Break(());
                    }
                }
            } else if m.topic == topics::CALIBRATION {
                match reader::decode_intrinsics(m.data, m.log_time) {
                    Ok((t, k)) => {
                        ix.intrinsics.insert(t, k);
                    }
                    Err(CalibrationError::NoUsableK) => {}
                    Err(e @ CalibrationError::UnknownDistortion(..)) => {
                        ix.undecodable = Some((m.topic.to_string(), e.to_string()));
                        return ControlFlow::Break(());
                    }
                    Err(CalibrationError::Undecodable(e)) => {
                        ix.undecodable = Some((m.topic.to_string(), e.to_string()));
                        return ControlFlow::Break(());
                    }
                }
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .map_err(|e| ExportError::BadInput(e.to_string()))?;
    Ok(ix)
}

/// Read one recording as an episode. Bad input: not an MCAP, an undecodable message, no
/// captures with a colour image, images of more than one size, an encoding the export cannot
/// read.
pub fn read_episode(path: &Path) -> Result<Episode, ExportError> {
    let shown = path.display();
    let rec = reader::read_recording(path).map_err(|e| ExportError::BadInput(e.to_string()))?;
    let ix = index_images(path)?;
    if let Some((topic, e)) = ix.undecodable {
        return Err(ExportError::BadInput(format!("{shown}: topic {topic}: bad message: {e}")));
    }
    if let Some((s, enc)) = ix.bad_encoding {
        return Err(ExportError::BadInput(format!(
            "{shown}: {} has encoding {enc}, which the export does not read",
            s.topic()
        )));
    }
    let Some(color) = ix.times.get(&Stream::Color).filter(|t| !t.is_empty()) else {
        return Err(ExportError::BadInput(format!(
            "{shown}: no captures: the recording has no {} images",
            topics::COLOR
        )));
    };
    if ix.sizes.len() > 1 {
        return Err(ExportError::BadInput(format!(
            "{shown}: images of more than one size ({}); a dataset has one size per stream",
            sizes_text(&ix.sizes)
        )));
    }
    let (width, height) = ix.sizes.first().copied().unwrap_or((0, 0));
    let streams: BTreeSet<Stream> = ix.times.keys().copied().collect();
    // A capture is a frame when every stream the recording has recorded its image.
    let times: Vec<u64> = color
        .iter()
        .copied()
        .filter(|t| streams.iter().all(|s| ix.times.get(s).is_some_and(|ts| ts.contains(t))))
        .collect();
    let incomplete = color.len() - times.len();
    if times.is_empty() {
        return Err(ExportError::BadInput(format!(
            "{shown}: no capture has all of its images recorded"
        )));
    }
    let frames: Vec<Frame> = times.iter().map(|&t| frame_at(&rec, &ix.intrinsics, t)).collect();
    let first_lens = frames.iter().find_map(|f| ix.intrinsics.get(&f.capture_ns));
    let meta = episode_meta(path, &rec, (width, height), &frames, first_lens, incomplete);
    Ok(Episode { path: path.to_path_buf(), frames, streams, width, height, meta })
}

fn sizes_text(sizes: &BTreeSet<(u32, u32)>) -> String {
    sizes.iter().map(|(w, h)| format!("{w}x{h}")).collect::<Vec<_>>().join(", ")
}

/// The element of `v` (sorted by `key`) nearest `t`.
fn nearest<T>(v: &[T], t: u64, key: impl Fn(&T) -> u64) -> Option<&T> {
    let i = v.partition_point(|x| key(x) < t);
    let after = v.get(i);
    let before = i.checked_sub(1).and_then(|j| v.get(j));
    match (before, after) {
        (Some(b), Some(a)) => Some(if t - key(b) <= key(a) - t { b } else { a }),
        (b, a) => b.or(a),
    }
}

/// The element of `v` (sorted by `key`) stamped exactly `t`.
fn exact<T>(v: &[T], t: u64, key: impl Fn(&T) -> u64) -> Option<&T> {
    let i = v.partition_point(|x| key(x) < t);
    v.get(i).filter(|x| key(x) == t)
}

fn frame_at(rec: &Recording, intrinsics: &BTreeMap<u64, Intrinsics>, t: u64) -> Frame {
    let nan7 = [f64::NAN; DOF];
    let tick = exact(&rec.capture_sync, t, |s| s.exposure_ns)
        .or_else(|| rec.capture_sync.iter().find(|s| s.exposure_ns == t))
        .map(|s| s.tick);
    let state_q = nearest(&rec.states, t, |s| s.t_ns).map_or(nan7, |s| s.q);
    // The setpoint the capture's tick sent; without a tick, the last one sent before exposure.
    let action_q = tick
        .and_then(|k| rec.setpoints.iter().rev().find(|s| s.tick == k))
        .or_else(|| {
            let i = rec.setpoints.partition_point(|s| s.t_ns <= t);
            i.checked_sub(1).map(|j| &rec.setpoints[j])
        })
        .map_or(nan7, |s| s.q);
    let camera_pose = exact(&rec.tf, t, |m| m.t_ns).map(|tf| tf.base_flange * tf.flange_camera);
    Frame {
        capture_ns: t,
        tick,
        state_q,
        action_q,
        camera_pose,
        target_gt: exact(&rec.pose_gt, t, |p| p.capture_ns).map(|p| p.pose),
        target_estimate: exact(&rec.pose_estimate, t, |p| p.capture_ns).map(|p| p.pose),
        intrinsics: intrinsics.get(&t).map(|k| [k.fx, k.fy, k.cx, k.cy]),
        distortion: intrinsics.get(&t).map(|k| k.distortion.coefficients),
    }
}

fn episode_meta(
    path: &Path,
    rec: &Recording,
    (w, h): (u32, u32),
    frames: &[Frame],
    first_lens: Option<&Intrinsics>,
    incomplete: usize,
) -> EpisodeMeta {
    let run = rec.metadata.get(topics::META_RUN);
    let get = |k: &str| run.and_then(|m| m.get(k)).cloned();
    let config: serde_json::Value = get("config")
        .and_then(|c| serde_json::from_str(&c).ok())
        .unwrap_or(serde_json::Value::Null);
    let config_str = |k: &str| config.get(k).and_then(|v| v.as_str()).map(str::to_string);
    let orbit = get("trajectory_meta")
        .and_then(|m| serde_json::from_str(&m).ok())
        .unwrap_or(serde_json::Value::Null);
    let scale = get("scale").and_then(|s| s.parse::<f64>().ok()).filter(|s| s.is_finite());
    let target_model = get("target_model").or_else(|| config_str("target_model"));
    let target_size_m = target_model
        .as_deref()
        .and_then(|m| hitl_perception::TargetModel::from_spec(m).ok())
        .map(|m| m.greatest_dimension_m());
    EpisodeMeta {
        recording: path
            .file_name()
            .map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()),
        complete: rec.end.as_ref().is_some_and(|e| e.complete),
        frames_read: rec.end.as_ref().map_or(0, |e| e.frames_read),
        frames_recorded: rec.end.as_ref().and_then(|e| e.frames_recorded),
        read_stopped: rec.end.as_ref().and_then(|e| e.truncated.clone()),
        trajectory_sha256: get("trajectory_sha256").filter(|s| !s.is_empty()),
        orbit,
        scale,
        camera_preset: config_str("camera_preset"),
        camera: config_str("camera"),
        target_model,
        target_size_m,
        target_size_lab_m: target_size_m.zip(scale).map(|(s, k)| s * k),
        image_size: [w, h],
        intrinsics: frames.iter().find_map(|f| f.intrinsics),
        distortion_model: first_lens.map(|k| k.distortion.model.name().to_string()),
        distortion: first_lens.map(|k| k.distortion.coefficients),
        incomplete_captures: incomplete,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_and_exact_pick_the_right_sample() {
        let v = [10u64, 20, 30];
        assert_eq!(nearest(&v, 14, |x| *x), Some(&10));
        assert_eq!(nearest(&v, 16, |x| *x), Some(&20));
        assert_eq!(nearest(&v, 99, |x| *x), Some(&30));
        assert_eq!(nearest(&v, 0, |x| *x), Some(&10));
        assert_eq!(nearest::<u64>(&[], 5, |x| *x), None);
        assert_eq!(exact(&v, 20, |x| *x), Some(&20));
        assert_eq!(exact(&v, 21, |x| *x), None);
    }
}
