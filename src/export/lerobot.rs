//! A LeRobot v3.0 dataset from recordings: one episode per recording, one frame per recorded
//! capture (docs/lerobot-export.md maps every feature).
//!
//! Layout (v3.0's chunked files; everything fits in chunk 000, file 000, which the loader finds
//! through the episodes table whatever its size):
//! `meta/info.json`, `meta/stats.json`, `meta/tasks.parquet`,
//! `meta/episodes/chunk-000/file-000.parquet`, `data/chunk-000/file-000.parquet`,
//! `videos/<key>/chunk-000/file-000.mp4`, and `meta/hitl.json` (the runs' own metadata).
//!
//! The dataset is written into a hidden folder next to `--out` and renamed into place at the
//! end: a failed export leaves nothing (the hidden folder is removed), never half a dataset.
//! What `--out` names is checked before anything is read ([`check_out`]): it never holds an input
//! recording, and `--force` replaces only a dataset this export wrote (never a file, never a
//! folder of other files).

use super::episode::{read_episode, Episode, Frame, Stream};
use super::tables::{tasks_table, Column, Table};
use super::video::{self, DepthQuant};
use super::{io_err, ExportError};
use hitl_hal::pose::{self, Pose};
use hitl_hal::DOF;
use serde_json::{json, Map, Value};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// LeRobot's dataset format version this export writes.
pub const CODEBASE_VERSION: &str = "v3.0";
pub const COLOR_KEY: &str = "observation.images.color";
pub const DEPTH_KEY: &str = "observation.images.depth";
pub const MASK_KEY: &str = "observation.images.mask";
const DATA_PATH: &str = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
const VIDEO_PATH: &str = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4";
const JOINTS: [&str; DOF] = ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6", "joint7"];
const POSE: [&str; 7] = ["x", "y", "z", "qx", "qy", "qz", "qw"];
/// `meta/hitl.json`'s `generator` starts with this: the marker [`recognise_dataset`] looks for.
pub const GENERATOR: &str = "hitl export lerobot";

/// The feature key of a stream's video.
pub fn video_key(s: Stream) -> &'static str {
    match s {
        Stream::Color => COLOR_KEY,
        Stream::Depth => DEPTH_KEY,
        Stream::Mask => MASK_KEY,
    }
}

/// What to export and where.
#[derive(Debug, Clone)]
pub struct ExportRequest {
    pub recordings: Vec<PathBuf>,
    pub out: PathBuf,
    /// Frames per second of the dataset's time grid (default: the captures' median rate); 1 to
    /// [`MAX_FPS`].
    pub fps: Option<u32>,
    /// The task text of every episode (default: from the trajectory's preset and range).
    pub task: Option<String>,
    /// Replace `out` if it exists.
    pub force: bool,
}

/// The highest `--fps` (and the highest rate the captures' median may give).
pub const MAX_FPS: u32 = 1000;

/// How much of one recording the export read (a damaged or cut file is read as far as it is
/// sound).
#[derive(Debug, Clone, serde::Serialize)]
pub struct RecordingRead {
    pub recording: PathBuf,
    /// The whole file was read.
    pub complete: bool,
    /// Captures read.
    pub frames_read: u64,
    /// Captures the file holds (its summary); null: unknown (no summary, a file cut short).
    pub frames_recorded: Option<u64>,
    /// Why reading stopped before the end.
    pub read_stopped: Option<String>,
}

/// What was written.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExportSummary {
    pub out: PathBuf,
    pub fps: u32,
    pub episodes: usize,
    pub frames: usize,
    /// Frames per episode, in episode order.
    pub episode_frames: Vec<usize>,
    /// Captures left out (an image not recorded), per episode.
    pub incomplete_captures: Vec<usize>,
    pub videos: Vec<String>,
    pub width: u32,
    pub height: u32,
    /// Per recording, how much of it was read.
    pub recordings: Vec<RecordingRead>,
    /// Every recording was read to its end.
    pub complete: bool,
}

/// Export recordings as one LeRobot v3.0 dataset.
pub fn export(req: &ExportRequest) -> Result<ExportSummary, ExportError> {
    if req.recordings.is_empty() {
        return Err(ExportError::BadInput("no recordings to export".into()));
    }
    if let Some(f) = req.fps.filter(|f| !(1..=MAX_FPS).contains(f)) {
        return Err(ExportError::BadInput(format!("--fps {f}: give 1 to {MAX_FPS}")));
    }
    let (out, existing) = check_out(&req.out, req.force, &req.recordings)?;
    // The hidden folder first: an output that cannot be written is refused before the work.
    let tmp = TempDir::beside(&out)?;
    let episodes = req.recordings.iter().map(|p| read_episode(p)).collect::<Result<Vec<_>, _>>()?;
    let (width, height, streams) = common_shape(&episodes)?;
    video::check_ffmpeg(streams.iter().copied())?;
    let fps = req.fps.unwrap_or_else(|| capture_fps(&episodes));

    let root = tmp.path.clone();
    let quant = DepthQuant::LEROBOT_DEFAULT;
    let logs = root.join(".ffmpeg");
    std::fs::create_dir_all(&logs).map_err(|e| io_err("cannot create", &logs, e))?;
    let path_of = |s: Stream| {
        root.join(
            VIDEO_PATH
                .replace("{video_key}", video_key(s))
                .replace("{chunk_index:03d}", "000")
                .replace("{file_index:03d}", "000"),
        )
    };
    let videos = video::encode(&episodes, (width, height), fps, &quant, path_of, &logs)?;
    let total: usize = episodes.iter().map(|e| e.frames.len()).sum();
    for (s, n) in &videos.frames {
        if *n != total as u64 {
            return Err(ExportError::Encoder(format!(
                "{} got {n} frames of {total} (an export bug)",
                video_key(*s)
            )));
        }
    }
    std::fs::remove_dir_all(&logs).map_err(|e| io_err("cannot remove", &logs, e))?;

    let tasks = task_texts(&episodes, req.task.as_deref());
    let (data, features) = frames_table(&episodes, &tasks, fps);
    let mut groups = Vec::new();
    let mut from = 0;
    for e in &episodes {
        groups.push((from, from + e.frames.len()));
        from += e.frames.len();
    }
    data.write(&root.join("data/chunk-000/file-000.parquet"), &groups)?;
    episodes_table(&episodes, &tasks, &streams, fps)
        .write(&root.join("meta/episodes/chunk-000/file-000.parquet"), &[])?;
    let unique = unique_tasks(&tasks);
    tasks_table(&unique).write(&root.join("meta/tasks.parquet"), &[])?;

    let mut all_features = features;
    for &s in &streams {
        all_features.insert(video_key(s).to_string(), video_feature(s, width, height, fps, &quant));
    }
    let n_ep = episodes.len();
    let info = json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": "xarm7",
        "total_episodes": n_ep,
        "total_frames": total,
        "total_tasks": unique.len(),
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": fps,
        "splits": {"train": format!("0:{n_ep}")},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH,
        "features": Value::Object(all_features),
    });
    write_json(&root.join("meta/info.json"), &info)?;
    write_json(&root.join("meta/stats.json"), &stats(&data))?;
    let sidecar = json!({
        "generator": format!("{GENERATOR} {}", env!("CARGO_PKG_VERSION")),
        "fps": fps,
        "fps_source": if req.fps.is_some() { "--fps" } else { "median capture interval" },
        "depth_quantisation": {"scale": "log", "min_m": quant.min_m, "max_m": quant.max_m,
                               "shift_m": quant.shift_m, "bits": 12},
        "episodes": episodes.iter().map(|e| &e.meta).collect::<Vec<_>>(),
    });
    write_json(&root.join("meta/hitl.json"), &sidecar)?;

    tmp.commit(&out, existing)?;
    let recordings: Vec<RecordingRead> = episodes
        .iter()
        .map(|e| RecordingRead {
            recording: e.path.clone(),
            complete: e.meta.complete,
            frames_read: e.meta.frames_read,
            frames_recorded: e.meta.frames_recorded,
            read_stopped: e.meta.read_stopped.clone(),
        })
        .collect();
    Ok(ExportSummary {
        complete: recordings.iter().all(|r| r.complete),
        recordings,
        out: req.out.clone(),
        fps,
        episodes: n_ep,
        frames: total,
        episode_frames: episodes.iter().map(|e| e.frames.len()).collect(),
        incomplete_captures: episodes.iter().map(|e| e.meta.incomplete_captures).collect(),
        videos: streams.iter().map(|s| video_key(*s).to_string()).collect(),
        width,
        height,
    })
}

/// What is at `--out` before the export, as [`check_out`] found it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    Nothing,
    EmptyFolder,
    /// A dataset this export wrote (replaced with `--force`).
    Dataset,
}

/// `path` made absolute with its symbolic links resolved, also when it does not exist yet (its
/// nearest existing ancestor is resolved).
fn resolved(path: &Path) -> std::io::Result<PathBuf> {
    let abs = std::path::absolute(path)?;
    let mut rest = Vec::new();
    let mut head = abs.as_path();
    loop {
        match std::fs::canonicalize(head) {
            Ok(c) => return Ok(rest.iter().rev().fold(c, |p, n| p.join(n))),
            Err(e) => match (head.parent(), head.file_name()) {
                (Some(parent), Some(name)) => {
                    rest.push(name.to_os_string());
                    head = parent;
                }
                _ => return Err(e),
            },
        }
    }
}

/// Check what `--out` names before anything is read or written; returns it resolved, and what
/// is there. Refused (exit 2): an `--out` that is or holds an input recording (whatever
/// `--force` says), a plain file or a link, a folder with files in it without `--force`, and
/// with `--force` a folder that is not a dataset this export wrote ([`recognise_dataset`]).
pub fn check_out(
    out: &Path,
    force: bool,
    inputs: &[PathBuf],
) -> Result<(PathBuf, Existing), ExportError> {
    let shown = out.display();
    let refuse = |why: String| Err(ExportError::Output(why));
    let abs = resolved(out)
        .map_err(|e| ExportError::Output(format!("--out {shown}: cannot resolve it: {e}")))?;
    if abs.parent().is_none() || abs.file_name().is_none() {
        return refuse(format!("--out {shown} is not a folder a dataset can be written to"));
    }
    for input in inputs {
        let Ok(r) = std::fs::canonicalize(input) else { continue };
        if r.starts_with(&abs) {
            return refuse(format!(
                "--out {shown} holds the input recording {}: the dataset would replace it; \
                 choose another --out",
                input.display()
            ));
        }
    }
    let meta = match std::fs::symlink_metadata(out) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((abs, Existing::Nothing)),
        Err(e) => return refuse(format!("--out {shown}: {e}")),
    };
    if !meta.is_dir() {
        return refuse(format!(
            "--out {shown} exists and is {}, not a dataset folder: the export never replaces \
             one, --force or not; choose another --out",
            if meta.file_type().is_symlink() { "a symbolic link" } else { "a file" }
        ));
    }
    let empty = std::fs::read_dir(out)
        .map_err(|e| ExportError::Output(format!("--out {shown}: {e}")))?
        .next()
        .is_none();
    if empty {
        return Ok((abs, Existing::EmptyFolder));
    }
    if !force {
        return refuse(format!(
            "--out {shown} exists: choose another --out, or pass --force to replace a dataset \
             hitl export wrote there"
        ));
    }
    match recognise_dataset(out) {
        Ok(()) => Ok((abs, Existing::Dataset)),
        Err(why) => refuse(format!(
            "--out {shown} is not a dataset hitl export wrote ({why}): --force replaces only \
             such a dataset; choose another --out"
        )),
    }
}

/// Whether `rel` (a path inside a dataset, `/`-separated) is a file this export writes.
fn is_dataset_file(rel: &str) -> bool {
    let parts: Vec<&str> = rel.split('/').collect();
    let numbered = |s: &str, prefix: &str, ext: &str| {
        s.strip_prefix(prefix)
            .and_then(|s| s.strip_suffix(ext))
            .is_some_and(|n| n.len() == 3 && n.bytes().all(|b| b.is_ascii_digit()))
    };
    let chunk_file =
        |c: &str, f: &str, ext: &str| numbered(c, "chunk-", "") && numbered(f, "file-", ext);
    match parts.as_slice() {
        ["meta", "info.json" | "stats.json" | "tasks.parquet" | "hitl.json"] => true,
        ["meta", "episodes", c, f] | ["data", c, f] => chunk_file(c, f, ".parquet"),
        ["videos", key, c, f] => {
            [COLOR_KEY, DEPTH_KEY, MASK_KEY].contains(key) && chunk_file(c, f, ".mp4")
        }
        _ => false,
    }
}

/// A folder is a dataset this export wrote when its `meta/info.json` is a LeRobot info (a
/// `codebase_version` and `features`), its `meta/hitl.json` names this exporter as its
/// `generator` (the marker), and it holds nothing but the files the export writes (no file of
/// anyone else's is replaced). Otherwise: why not.
pub fn recognise_dataset(dir: &Path) -> Result<(), String> {
    let json = |rel: &str| -> Result<Value, String> {
        let text = std::fs::read_to_string(dir.join(rel)).map_err(|e| format!("{rel}: {e}"))?;
        serde_json::from_str(&text).map_err(|e| format!("{rel}: {e}"))
    };
    let info = json("meta/info.json")?;
    if !(info["codebase_version"].is_string() && info["features"].is_object()) {
        return Err("meta/info.json is not a LeRobot dataset's".into());
    }
    let generator = json("meta/hitl.json")?["generator"].as_str().unwrap_or("").to_string();
    if !generator.starts_with(GENERATOR) {
        return Err(format!("meta/hitl.json does not name {GENERATOR:?} as its generator"));
    }
    let mut foreign = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).map_err(|e| format!("{}: {e}", d.display()))? {
            let entry = entry.map_err(|e| format!("{}: {e}", d.display()))?;
            let path = entry.path();
            let kind = entry.file_type().map_err(|e| format!("{}: {e}", path.display()))?;
            let rel = path
                .strip_prefix(dir)
                .map(|r| r.to_string_lossy().replace('\\', "/"))
                .unwrap_or_default();
            if kind.is_dir() {
                stack.push(path);
            } else if !(kind.is_file() && is_dataset_file(&rel)) {
                foreign.push(rel);
            }
        }
    }
    if foreign.is_empty() {
        return Ok(());
    }
    foreign.sort();
    let more =
        if foreign.len() > 3 { format!(" and {} more", foreign.len() - 3) } else { String::new() };
    foreign.truncate(3);
    Err(format!("it holds files the export did not write: {}{more}", foreign.join(", ")))
}

/// One image size and one set of streams for the whole dataset.
fn common_shape(episodes: &[Episode]) -> Result<(u32, u32, BTreeSet<Stream>), ExportError> {
    let first = &episodes[0];
    for e in &episodes[1..] {
        if (e.width, e.height) != (first.width, first.height) {
            return Err(ExportError::BadInput(format!(
                "mixed image sizes across recordings: {} is {}x{}, {} is {}x{}; export them \
                 into separate datasets",
                first.path.display(),
                first.width,
                first.height,
                e.path.display(),
                e.width,
                e.height
            )));
        }
        if e.streams != first.streams {
            let names =
                |s: &BTreeSet<Stream>| s.iter().map(|s| s.topic()).collect::<Vec<_>>().join(", ");
            return Err(ExportError::BadInput(format!(
                "mixed image streams across recordings: {} has {}, {} has {}",
                first.path.display(),
                names(&first.streams),
                e.path.display(),
                names(&e.streams)
            )));
        }
    }
    Ok((first.width, first.height, first.streams.clone()))
}

/// The dataset's rate: the median capture interval over all recordings, rounded to whole frames
/// per second (at least 1).
pub fn capture_fps(episodes: &[Episode]) -> u32 {
    let mut d: Vec<u64> = episodes
        .iter()
        .flat_map(|e| e.frames.windows(2).map(|w| w[1].capture_ns - w[0].capture_ns))
        .filter(|d| *d > 0)
        .collect();
    if d.is_empty() {
        return 1;
    }
    d.sort_unstable();
    let median = d[d.len() / 2] as f64;
    (1e9 / median).round().clamp(1.0, f64::from(MAX_FPS)) as u32
}

fn task_texts(episodes: &[Episode], task: Option<&str>) -> Vec<String> {
    episodes
        .iter()
        .map(|e| match task {
            Some(t) => t.to_string(),
            None => {
                let preset = e.meta.orbit.get("preset").and_then(Value::as_str);
                let range = e.meta.orbit.get("range_m").and_then(Value::as_f64);
                match (preset, range) {
                    (Some(p), Some(r)) => format!("{p} of the target at {r} m range"),
                    (Some(p), None) => format!("{p} of the target"),
                    _ => "trajectory played around the target".to_string(),
                }
            }
        })
        .collect()
}

fn unique_tasks(tasks: &[String]) -> Vec<String> {
    let mut u: Vec<String> = Vec::new();
    for t in tasks {
        if !u.contains(t) {
            u.push(t.clone());
        }
    }
    u
}

fn pose7(p: Option<Pose>) -> [f32; 7] {
    p.map_or([f32::NAN; 7], |p| {
        let [x, y, z]: [f64; 3] = p.translation.vector.into();
        let [qx, qy, qz, qw] = pose::quat_xyzw(&p);
        [x, y, z, qx, qy, qz, qw].map(|v| v as f32)
    })
}

fn feature(dtype: &str, n: usize, names: Option<&[&str]>) -> Value {
    json!({"dtype": dtype, "shape": [n], "names": names})
}

/// Which pose of a frame a column holds.
type PoseOf = fn(&Frame) -> Option<Pose>;

/// The frames table and its features (in the same order).
fn frames_table(episodes: &[Episode], tasks: &[String], fps: u32) -> (Table, Map<String, Value>) {
    let unique = unique_tasks(tasks);
    let rows = |f: &dyn Fn(&Frame) -> Vec<f32>| -> Vec<f32> {
        episodes.iter().flat_map(|e| e.frames.iter().flat_map(f)).collect()
    };
    let per_frame = |f: &dyn Fn(usize, usize, &Episode, &Frame) -> i64| -> Vec<i64> {
        let mut out = Vec::new();
        for (ei, e) in episodes.iter().enumerate() {
            for (fi, fr) in e.frames.iter().enumerate() {
                out.push(f(ei, fi, e, fr));
            }
        }
        out
    };
    let mut t = Table::default();
    let mut ft = Map::new();
    let mut add = |name: &str, c: Column, f: Value| {
        t.push(name, c);
        ft.insert(name.to_string(), f);
    };
    let to32 = |q: [f64; DOF]| q.map(|v| v as f32).to_vec();
    add(
        "observation.state",
        Column::F32s(DOF, rows(&|f| to32(f.state_q))),
        feature("float32", DOF, Some(&JOINTS[..])),
    );
    add(
        "action",
        Column::F32s(DOF, rows(&|f| to32(f.action_q))),
        feature("float32", DOF, Some(&JOINTS[..])),
    );
    let poses: [(&str, PoseOf); 3] = [
        ("observation.camera_pose", |f| f.camera_pose),
        ("observation.target_pose_gt", |f| f.target_gt),
        ("observation.target_pose_estimate", |f| f.target_estimate),
    ];
    for (name, pose) in poses {
        let c = Column::F32s(7, rows(&|f| pose7(pose(f)).to_vec()));
        add(name, c, feature("float32", 7, Some(&POSE[..])));
    }
    add(
        "observation.target_pose_estimate_valid",
        Column::Bool(
            episodes
                .iter()
                .flat_map(|e| e.frames.iter().map(|f| f.target_estimate.is_some()))
                .collect(),
        ),
        feature("bool", 1, None),
    );
    add(
        "observation.camera_intrinsics",
        Column::F32s(
            4,
            rows(&|f| f.intrinsics.map_or([f32::NAN; 4], |k| k.map(|v| v as f32)).to_vec()),
        ),
        feature("float32", 4, Some(&["fx", "fy", "cx", "cy"][..])),
    );
    add(
        "observation.camera_distortion",
        Column::F32s(
            8,
            rows(&|f| f.distortion.map_or([f32::NAN; 8], |d| d.map(|v| v as f32)).to_vec()),
        ),
        feature("float32", 8, Some(&["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"][..])),
    );
    add(
        "capture_time_s",
        Column::F64(
            episodes
                .iter()
                .flat_map(|e| {
                    let t0 = e.frames[0].capture_ns;
                    e.frames.iter().map(move |f| (f.capture_ns - t0) as f64 * 1e-9)
                })
                .collect(),
        ),
        feature("float64", 1, None),
    );
    add(
        "capture_time_ns",
        Column::I64(per_frame(&|_, _, _, f| f.capture_ns as i64)),
        feature("int64", 1, None),
    );
    add(
        "capture_tick",
        Column::I64(per_frame(&|_, _, _, f| f.tick.map_or(-1, |k| k as i64))),
        feature("int64", 1, None),
    );
    add(
        "timestamp",
        Column::F32(
            per_frame(&|_, fi, _, _| fi as i64)
                .into_iter()
                .map(|i| (i as f64 / f64::from(fps)) as f32)
                .collect(),
        ),
        feature("float32", 1, None),
    );
    add("frame_index", Column::I64(per_frame(&|_, fi, _, _| fi as i64)), feature("int64", 1, None));
    add(
        "episode_index",
        Column::I64(per_frame(&|ei, _, _, _| ei as i64)),
        feature("int64", 1, None),
    );
    let total: usize = episodes.iter().map(|e| e.frames.len()).sum();
    add("index", Column::I64((0..total as i64).collect()), feature("int64", 1, None));
    add(
        "task_index",
        Column::I64(per_frame(&|ei, _, _, _| {
            unique.iter().position(|u| *u == tasks[ei]).unwrap_or(0) as i64
        })),
        feature("int64", 1, None),
    );
    (t, ft)
}

fn episodes_table(
    episodes: &[Episode],
    tasks: &[String],
    streams: &BTreeSet<Stream>,
    fps: u32,
) -> Table {
    let n = episodes.len();
    let lengths: Vec<i64> = episodes.iter().map(|e| e.frames.len() as i64).collect();
    let mut from = Vec::with_capacity(n);
    let mut acc = 0i64;
    for l in &lengths {
        from.push(acc);
        acc += l;
    }
    let to: Vec<i64> = from.iter().zip(&lengths).map(|(f, l)| f + l).collect();
    let zeros = Column::I64(vec![0; n]);
    let mut t = Table::default();
    t.push("episode_index", Column::I64((0..n as i64).collect()));
    t.push("tasks", Column::StrLists(tasks.iter().map(|t| vec![t.clone()]).collect()));
    t.push("length", Column::I64(lengths.clone()));
    t.push("data/chunk_index", zeros.clone());
    t.push("data/file_index", zeros.clone());
    t.push("dataset_from_index", Column::I64(from.clone()));
    t.push("dataset_to_index", Column::I64(to.clone()));
    let secs = |v: &[i64]| Column::F64(v.iter().map(|i| *i as f64 / f64::from(fps)).collect());
    for &s in streams {
        let k = video_key(s);
        t.push(&format!("videos/{k}/chunk_index"), zeros.clone());
        t.push(&format!("videos/{k}/file_index"), zeros.clone());
        t.push(&format!("videos/{k}/from_timestamp"), secs(&from));
        t.push(&format!("videos/{k}/to_timestamp"), secs(&to));
    }
    t.push("meta/episodes/chunk_index", zeros.clone());
    t.push("meta/episodes/file_index", zeros);
    let m = |f: &dyn Fn(&Episode) -> Option<String>| Column::Str(episodes.iter().map(f).collect());
    let x = |f: &dyn Fn(&Episode) -> Option<f64>| {
        Column::F64(episodes.iter().map(|e| f(e).unwrap_or(f64::NAN)).collect())
    };
    t.push("hitl/recording", m(&|e| Some(e.meta.recording.clone())));
    t.push("hitl/complete", Column::Bool(episodes.iter().map(|e| e.meta.complete).collect()));
    t.push("hitl/trajectory_sha256", m(&|e| e.meta.trajectory_sha256.clone()));
    t.push("hitl/orbit", m(&|e| (!e.meta.orbit.is_null()).then(|| e.meta.orbit.to_string())));
    t.push("hitl/scale", x(&|e| e.meta.scale));
    t.push("hitl/camera", m(&|e| e.meta.camera.clone()));
    t.push("hitl/camera_preset", m(&|e| e.meta.camera_preset.clone()));
    t.push("hitl/target_model", m(&|e| e.meta.target_model.clone()));
    t.push("hitl/target_size_m", x(&|e| e.meta.target_size_m));
    t.push("hitl/target_size_lab_m", x(&|e| e.meta.target_size_lab_m));
    t.push(
        "hitl/intrinsics",
        Column::F64s(
            4,
            episodes.iter().flat_map(|e| e.meta.intrinsics.unwrap_or([f64::NAN; 4])).collect(),
        ),
    );
    t.push("hitl/distortion_model", m(&|e| e.meta.distortion_model.clone()));
    t.push(
        "hitl/distortion",
        Column::F64s(
            8,
            episodes.iter().flat_map(|e| e.meta.distortion.unwrap_or([f64::NAN; 8])).collect(),
        ),
    );
    t.push(
        "hitl/incomplete_captures",
        Column::I64(episodes.iter().map(|e| e.meta.incomplete_captures as i64).collect()),
    );
    t
}

fn video_feature(s: Stream, w: u32, h: u32, fps: u32, q: &DepthQuant) -> Value {
    let f = video::format_of(s, w, h);
    let mut info = json!({
        "video.height": h,
        "video.width": w,
        "video.codec": f.codec,
        "video.pix_fmt": f.pix_fmt,
        "video.fps": fps,
        "video.channels": f.channels,
        "has_audio": false,
        "is_depth_map": s == Stream::Depth,
    });
    if s == Stream::Depth {
        if let Some(o) = info.as_object_mut() {
            o.insert("depth_unit".into(), json!("m"));
            o.insert("video.depth_min".into(), json!(q.min_m));
            o.insert("video.depth_max".into(), json!(q.max_m));
            o.insert("video.shift".into(), json!(q.shift_m));
            o.insert("video.use_log".into(), json!(true));
        }
    }
    json!({
        "dtype": "video",
        "shape": [h, w, f.channels],
        "names": ["height", "width", "channels"],
        "info": info,
    })
}

/// Per-dimension min, max, mean, std and count of every numeric column (NaN left out), as
/// LeRobot's `meta/stats.json`. Video features have none (docs/lerobot-export.md).
fn stats(data: &Table) -> Value {
    let mut out = Map::new();
    for (name, c) in &data.columns {
        let (n, v): (usize, Vec<f64>) = match c {
            Column::F32(v) => (1, v.iter().map(|x| f64::from(*x)).collect()),
            Column::F64(v) => (1, v.clone()),
            Column::I64(v) => (1, v.iter().map(|x| *x as f64).collect()),
            Column::F32s(n, v) => (*n, v.iter().map(|x| f64::from(*x)).collect()),
            Column::F64s(n, v) => (*n, v.clone()),
            _ => continue,
        };
        let dims: Vec<Vec<f64>> = (0..n)
            .map(|d| v.iter().skip(d).step_by(n).copied().filter(|x| x.is_finite()).collect())
            .collect();
        let each = |f: &dyn Fn(&[f64]) -> f64| -> Vec<Value> {
            dims.iter().map(|d| if d.is_empty() { Value::Null } else { json!(f(d)) }).collect()
        };
        let mean = |d: &[f64]| d.iter().sum::<f64>() / d.len() as f64;
        out.insert(
            name.clone(),
            json!({
                "min": each(&|d| d.iter().copied().fold(f64::INFINITY, f64::min)),
                "max": each(&|d| d.iter().copied().fold(f64::NEG_INFINITY, f64::max)),
                "mean": each(&mean),
                "std": each(&|d| {
                    let m = mean(d);
                    (d.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / d.len() as f64).sqrt()
                }),
                "count": [v.len() / n.max(1)],
            }),
        );
    }
    Value::Object(out)
}

fn write_json(path: &Path, v: &Value) -> Result<(), ExportError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| io_err("cannot create", dir, e))?;
    }
    let text = serde_json::to_string_pretty(v).map_err(|e| io_err("cannot encode", path, e))?;
    std::fs::write(path, text + "\n").map_err(|e| io_err("cannot write", path, e))
}

/// The hidden folder an export is written into; removed unless committed, with the folders
/// above it that were created for it.
struct TempDir {
    path: PathBuf,
    committed: bool,
    /// Folders created for `--out`'s parent, innermost first.
    created: Vec<PathBuf>,
}

impl TempDir {
    fn beside(out: &Path) -> Result<TempDir, ExportError> {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let created: Vec<PathBuf> =
            parent.ancestors().take_while(|a| !a.exists()).map(Path::to_path_buf).collect();
        std::fs::create_dir_all(parent).map_err(|e| {
            ExportError::Output(format!("cannot create {} (for --out): {e}", parent.display()))
        })?;
        let name = out.file_name().map_or("dataset".into(), |n| n.to_string_lossy().into_owned());
        let path = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if path.exists() {
            std::fs::remove_dir_all(&path).map_err(|e| io_err("cannot remove", &path, e))?;
        }
        std::fs::create_dir(&path).map_err(|e| {
            ExportError::Output(format!(
                "cannot write into {} (for --out {}): {e}",
                parent.display(),
                out.display()
            ))
        })?;
        Ok(TempDir { path, committed: false, created })
    }

    /// Rename into place. `existing` is what [`check_out`] found at `out`: an empty folder is
    /// removed first; a dataset is moved aside, the new one renamed in, and the old one removed
    /// (moved back if the rename fails). Anything else there now appeared during the export and
    /// is left alone.
    fn commit(mut self, out: &Path, existing: Existing) -> Result<(), ExportError> {
        let appeared = || {
            ExportError::Output(format!(
                "{} appeared or changed during the export; the new dataset is not written",
                out.display()
            ))
        };
        let mut aside = None;
        match existing {
            Existing::Nothing => {
                if std::fs::symlink_metadata(out).is_ok() {
                    return Err(appeared());
                }
            }
            Existing::EmptyFolder => std::fs::remove_dir(out).map_err(|_| appeared())?,
            Existing::Dataset => {
                recognise_dataset(out).map_err(|_| appeared())?;
                let name = out.file_name().map_or("dataset".into(), |n| n.to_string_lossy());
                let old =
                    self.path.with_file_name(format!(".{name}.replaced-{}", std::process::id()));
                std::fs::rename(out, &old).map_err(|e| io_err("cannot move aside", out, e))?;
                aside = Some(old);
            }
        }
        if let Err(e) = std::fs::rename(&self.path, out) {
            if let Some(old) = &aside {
                let _ = std::fs::rename(old, out);
            }
            return Err(io_err("cannot rename into", out, e));
        }
        self.committed = true;
        if let Some(old) = aside {
            std::fs::remove_dir_all(&old).map_err(|e| {
                ExportError::Io(format!(
                    "the dataset is written to {}, but the one it replaced could not be removed \
                     from {}: {e}",
                    out.display(),
                    old.display()
                ))
            })?;
        }
        Ok(())
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.path);
            for d in &self.created {
                let _ = std::fs::remove_dir(d);
            }
        }
    }
}
