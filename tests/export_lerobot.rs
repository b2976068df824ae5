//! `hitl export lerobot`: a recording made by `hitl run` on the stub becomes a LeRobot v3.0 dataset
//! that `scripts/validate_lerobot.py` (the loader's checks, with pyarrow and PyAV) accepts, with
//! one parquet row and one video frame per recorded capture; depth read back through LeRobot's
//! dequantisation lands within one quantum of what was recorded; bad input gets exit 2 and leaves
//! nothing behind; `--force` replaces only a dataset the export wrote, never an input recording, a
//! file or a folder of anyone else's files; every row of docs/lerobot-export.md's exit codes.
//!
//! Needs ffmpeg (libx264, libx265) and the test venv's pyarrow and av (`make setup`).

use hitl::export::episode::Stream;
use hitl::export::tables::{Column, Table};
use hitl::export::video::{format_of, DepthQuant};
use hitl_hal::{Intrinsics, Pose};
use hitl_record::reader::read_recording;
use hitl_record::{DepthImage, FrameRecord, Plane, PoseStamped, Recorder, RunMetadata, TfMsg};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{hitl, plan_flyaround, SIM_CAPTURE_RUN, SIM_CLOCK};

fn python() -> PathBuf {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    if venv.exists() {
        venv
    } else {
        PathBuf::from("python3")
    }
}

/// Runs the validator on a dataset; returns its exit code and verdict.
fn validate(dataset: &Path) -> (Option<i32>, Value) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/validate_lerobot.py");
    let out = Command::new(python())
        .arg(script)
        .arg(dataset)
        .arg("--json")
        .output()
        .expect("run the validator");
    let text = String::from_utf8_lossy(&out.stdout);
    let verdict = serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!("validator said no JSON ({e}): {text}\n{}", String::from_utf8_lossy(&out.stderr))
    });
    (out.status.code(), verdict)
}

fn export(args: &[&str]) -> (Option<i32>, String) {
    let out = hitl(&[&["export", "lerobot"][..], args].concat());
    let text =
        format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.code(), text)
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Nothing but `keep` in `dir`: no dataset, no half-written hidden folder.
fn only(dir: &Path, keep: &[&str]) {
    let names: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect();
    assert!(names.is_empty(), "left behind: {names:?}");
}

#[test]
fn a_stub_run_exports_to_a_dataset_the_validator_accepts_one_row_and_frame_per_capture() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("fly.npz");
    let mcap = dir.path().join("run.mcap");
    plan_flyaround(&traj, "10", "20");
    // On the simulated clock the run does not depend on the machine's load: it completes.
    let run = [&["run", s(&traj), "--record", s(&mcap)][..], &SIM_CAPTURE_RUN, &SIM_CLOCK];
    let run = hitl(&run.concat());
    let said =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert_eq!(run.status.code(), Some(0), "{said}");
    let rec = read_recording(&mcap).expect("recording");
    let captures = rec.topic_counts.get("/camera/color").copied().unwrap_or(0);
    assert!(captures >= 2, "{captures} captures: {said}");

    let ds = dir.path().join("ds");
    let (code, text) = export(&[s(&mcap), "--out", s(&ds)]);
    assert_eq!(code, Some(0), "{text}");
    let (code, v) = validate(&ds);
    assert_eq!(code, Some(0), "{v}");
    assert_eq!(v["ok"], true, "{v}");
    assert_eq!(v["episodes"], 1);
    assert_eq!(v["frames"].as_u64(), Some(captures), "one row per recorded capture");
    assert_eq!(v["rows"].as_u64(), Some(captures));
    for key in ["observation.images.color", "observation.images.depth", "observation.images.mask"] {
        assert_eq!(v["video_frames"][key].as_u64(), Some(captures), "{key}: {v}");
    }
    // The true capture times, in order, are the recording's.
    let times: Vec<u64> = v["capture_time_ns"]
        .as_array()
        .expect("capture times")
        .iter()
        .map(|t| t.as_u64().expect("ns"))
        .collect();
    let gt_times: Vec<u64> = rec.pose_gt.iter().map(|p| p.capture_ns).collect();
    assert_eq!(times, gt_times);
    // Depth under the mask, read back as LeRobot does, is where the ground truth puts the target
    // (the visible surface is within the model's size of its centre; a quantum is about 1 mm here).
    let info: Value = serde_json::from_str(
        &std::fs::read_to_string(ds.join("meta/info.json")).expect("info.json"),
    )
    .expect("json");
    let size: f64 = {
        let hitl: Value = serde_json::from_str(
            &std::fs::read_to_string(ds.join("meta/hitl.json")).expect("hitl.json"),
        )
        .expect("json");
        let e = &hitl["episodes"][0];
        assert_eq!(e["camera_preset"], "wfov", "{e}");
        assert!(e["orbit"]["range_m"].as_f64().is_some(), "orbit metadata: {e}");
        e["target_size_lab_m"].as_f64().expect("target size")
    };
    assert_eq!(info["features"]["observation.images.depth"]["info"]["is_depth_map"], true);
    let medians = v["masked_depth_median_m"].as_array().expect("depth medians");
    assert_eq!(medians.len() as u64, captures);
    for (m, gt) in medians.iter().zip(&rec.pose_gt) {
        let z = gt.pose.translation.z;
        let d = m.as_f64().expect("the mask covers the target in every frame");
        assert!((d - z).abs() < size, "median depth {d} m, target centre at {z} m, size {size} m");
    }

    // Two recordings: two episodes, rows and frames for both, contiguous index ranges.
    let ds2 = dir.path().join("ds2");
    let (code, text) = export(&[s(&mcap), s(&mcap), "--out", s(&ds2), "--task", "inspect"]);
    assert_eq!(code, Some(0), "{text}");
    let (code, v) = validate(&ds2);
    assert_eq!(code, Some(0), "{v}");
    assert_eq!(v["episodes"], 2);
    assert_eq!(v["frames"].as_u64(), Some(2 * captures));
    assert_eq!(v["video_frames"]["observation.images.color"].as_u64(), Some(2 * captures));
    assert_eq!(v["tasks"], serde_json::json!(["inspect"]));

    // An existing --out is refused (exit 2) and left as it was; --force replaces it.
    let (code, text) = export(&[s(&mcap), "--out", s(&ds)]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("exists"), "{text}");
    let (code, text) = export(&[s(&mcap), "--out", s(&ds), "--force", "--fps", "7"]);
    assert_eq!(code, Some(0), "{text}");
    assert_eq!(validate(&ds).1["fps"], 7);
    only(dir.path(), &["fly.npz", "run.mcap", "ds", "ds2"]);
}

/// A recording of `n` synthetic captures `w` x `h`, 100 ms apart, depth `depth_m(k)` under a
/// centred mask and 0 (no return) elsewhere.
fn synthetic(path: &Path, n: u64, (w, h): (u32, u32), depth_m: impl Fn(u64) -> f32) {
    let (rec, tel) = Recorder::spawn(path, &RunMetadata::default()).expect("recorder");
    let px = (w * h) as usize;
    for k in 0..n {
        let inside = |i: usize| {
            let (u, v) = ((i % w as usize) as u32, (i / w as usize) as u32);
            u >= w / 4 && u < 3 * w / 4 && v >= h / 4 && v < 3 * h / 4
        };
        let mask: Vec<u8> = (0..px).map(|i| if inside(i) { 255 } else { 0 }).collect();
        let depth: Vec<f32> = (0..px).map(|i| if inside(i) { depth_m(k) } else { 0.0 }).collect();
        let t = 1_000_000_000 + k * 100_000_000;
        let pose = Pose::translation(0.0, 0.0, f64::from(depth_m(k)));
        let frame = FrameRecord {
            tick: 10 * k,
            capture_ns: t,
            intrinsics: Intrinsics::pinhole(w, h, 30.0, 30.0, 16.0, 12.0),
            color: Some(Plane { width: w, height: h, data: vec![(k * 20) as u8; px * 3].into() }),
            depth: Some(DepthImage::Metres(Plane { width: w, height: h, data: depth.into() })),
            mask: Some(Plane { width: w, height: h, data: mask.into() }),
            gt_pose: Some(pose),
            tf: Some(TfMsg {
                t_ns: t,
                base_flange: Pose::identity(),
                flange_camera: Pose::identity(),
                base_target: pose,
            }),
            trigger_ns: Some(t - 1_000_000),
            light_level: None,
        };
        assert!(tel.push_frame(frame));
        tel.push_pose_estimate(&PoseStamped { capture_ns: t, pose });
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    rec.finish().expect("close the recording");
}

#[test]
fn recorded_depth_reads_back_through_lerobots_dequantisation_within_a_quantum() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mcap = dir.path().join("synthetic.mcap");
    let depth = |k: u64| 0.35 + 0.45 * k as f32;
    synthetic(&mcap, 5, (32, 24), depth);
    let ds = dir.path().join("ds");
    let (code, text) = export(&[s(&mcap), "--out", s(&ds)]);
    assert_eq!(code, Some(0), "{text}");
    let (code, v) = validate(&ds);
    assert_eq!(code, Some(0), "{v}");
    assert_eq!(v["fps"], 10, "100 ms between captures");
    assert_eq!(v["frames"], 5);
    for (k, m) in v["masked_depth_median_m"].as_array().expect("medians").iter().enumerate() {
        let d = f64::from(depth(k as u64));
        // One quantum of LeRobot's log scale at d: (d + 3.5) * ln(13.5 / 3.51) / 4095.
        let quantum = (d + 3.5) * (13.5f64 / 3.51).ln() / 4095.0;
        let got = m.as_f64().expect("median");
        assert!((got - d).abs() <= 0.5 * quantum + 1e-6, "frame {k}: {got} m for {d} m");
    }
    // The estimate and ground truth columns carry the recorded poses.
    let gt = v["observation.target_pose_gt"].as_array().expect("gt");
    assert!((gt[4][2].as_f64().expect("z") - f64::from(depth(4))).abs() < 1e-6, "{}", gt[4]);
}

#[test]
fn bad_input_gets_exit_2_a_clear_error_and_leaves_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let out = d.join("ds");

    let text_file = d.join("notes.mcap");
    std::fs::write(&text_file, "not a recording").expect("write");
    let (code, text) = export(&[s(&text_file), "--out", s(&out)]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("not an MCAP"), "{text}");

    let empty = d.join("empty.mcap");
    let (rec, _tel) = Recorder::spawn(&empty, &RunMetadata::default()).expect("recorder");
    rec.finish().expect("close");
    let (code, text) = export(&[s(&empty), "--out", s(&out)]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("no captures"), "{text}");

    let (a, b) = (d.join("a.mcap"), d.join("b.mcap"));
    synthetic(&a, 2, (32, 24), |_| 1.0);
    synthetic(&b, 2, (40, 30), |_| 1.0);
    let (code, text) = export(&[s(&a), s(&b), "--out", s(&out)]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("mixed image sizes") && text.contains("40x30"), "{text}");

    let missing = d.join("missing.mcap");
    let (code, text) = export(&[s(&missing), "--out", s(&out)]);
    assert_eq!(code, Some(2), "{text}");
    only(d, &["notes.mcap", "empty.mcap", "a.mcap", "b.mcap"]);
}

#[test]
fn depth_codes_follow_lerobots_log_scale_and_read_back_within_half_a_quantum() {
    let q = DepthQuant::LEROBOT_DEFAULT;
    assert_eq!(q.code(0.0), 0, "no return");
    assert_eq!(q.code(f32::NAN), 0);
    assert_eq!(q.code(0.01), 0, "min is code 0");
    assert_eq!(q.code(10.0), DepthQuant::QMAX, "max is the top code");
    assert_eq!(q.code(50.0), DepthQuant::QMAX, "clipped");
    // 1 m: (ln 4.5 - ln 3.51) / (ln 13.5 - ln 3.51) * 4095 = 755.3 -> 755.
    assert_eq!(q.code(1.0), 755);
    for d in [0.3f32, 0.8, 1.0, 1.7, 2.5, 4.0] {
        let back = q.depth_m(q.code(d));
        // One quantum at d is (d + shift) * ln(13.5 / 3.51) / 4095 (under 2.5 mm at 4 m).
        let quantum = (f64::from(d) + 3.5) * ((13.5f64 / 3.51).ln() / 4095.0);
        assert!((back - f64::from(d)).abs() <= 0.5 * quantum + 1e-9, "{d} -> {back}");
    }
}

#[test]
fn colour_of_an_odd_size_keeps_full_chroma() {
    assert_eq!(format_of(Stream::Color, 320, 256).pix_fmt, "yuv420p");
    assert_eq!(format_of(Stream::Color, 321, 256).pix_fmt, "yuv444p");
    assert_eq!(format_of(Stream::Depth, 321, 256).pix_fmt, "gray12le");
}

#[test]
fn a_table_refuses_columns_of_different_lengths() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut t = Table::default();
    t.push("a", Column::I64(vec![1, 2]));
    t.push("b", Column::F32s(7, vec![0.0; 7]));
    let e = t.write(&dir.path().join("x.parquet"), &[]).expect_err("lengths differ");
    assert!(e.to_string().contains("column b"), "{e}");
    t.columns[1].1 = Column::F32s(7, vec![0.0; 14]);
    t.write(&dir.path().join("x.parquet"), &[(0, 1), (1, 2)]).expect("writes");
}

/// Every file under `dir` with its bytes, to show nothing was touched.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("read dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let bytes = std::fs::read(&p).expect("read");
                out.push((p, bytes));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn force_replaces_only_a_dataset_the_export_wrote_never_an_input_or_anyone_elses_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    // `make demo`'s layout: the recording, its trajectory and its report in one folder.
    let demo = d.join("demo");
    std::fs::create_dir_all(demo.join("report")).expect("mkdir");
    let mcap = demo.join("run.mcap");
    synthetic(&mcap, 3, (32, 24), |_| 1.0);
    std::fs::write(demo.join("fly.npz"), "trajectory").expect("write");
    std::fs::write(demo.join("report/index.html"), "report").expect("write");
    let before = snapshot(&demo);

    // --out the folder the recording is in, or the recording itself: refused, --force or not.
    for out in [&demo, &mcap] {
        for force in [&[][..], &["--force"][..]] {
            let (code, text) = export(&[&[s(&mcap), "--out", s(out)][..], force].concat());
            assert_eq!(code, Some(2), "{text}");
            assert!(text.contains("holds the input recording"), "{text}");
            assert!(
                snapshot(&demo) == before,
                "--out {} {force:?} touched the input",
                out.display()
            );
        }
    }
    // The same through another spelling of the path (a `..` and a symbolic link).
    let link = d.join("link");
    std::os::unix::fs::symlink(&demo, &link).expect("symlink");
    let (code, text) = export(&[s(&mcap), "--out", s(&link.join("../demo")), "--force"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(snapshot(&demo) == before);

    // A folder of someone's files: refused with --force, its files as they were.
    let thesis = d.join("thesis");
    std::fs::create_dir(&thesis).expect("mkdir");
    std::fs::write(thesis.join("thesis.txt"), "four years").expect("write");
    let (code, text) = export(&[s(&mcap), "--out", s(&thesis), "--force"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("not a dataset hitl export wrote"), "{text}");
    assert_eq!(std::fs::read_to_string(thesis.join("thesis.txt")).expect("read"), "four years");

    // A plain file: refused, --force or not, left as it was, nothing written beside it.
    let file = d.join("ds.txt");
    std::fs::write(&file, "keep").expect("write");
    for force in [&[][..], &["--force"][..]] {
        let (code, text) = export(&[&[s(&mcap), "--out", s(&file)][..], force].concat());
        assert_eq!(code, Some(2), "{text}");
        assert!(text.contains("is a file"), "{text}");
    }
    assert_eq!(std::fs::read_to_string(&file).expect("read"), "keep");

    // A dataset the export wrote: replaced with --force ...
    let ds = d.join("ds");
    let (code, text) = export(&[s(&mcap), "--out", s(&ds)]);
    assert_eq!(code, Some(0), "{text}");
    let (code, text) = export(&[s(&mcap), "--out", s(&ds), "--force", "--fps", "3"]);
    assert_eq!(code, Some(0), "{text}");
    let info = std::fs::read_to_string(ds.join("meta/info.json")).expect("info.json");
    assert_eq!(serde_json::from_str::<Value>(&info).expect("json")["fps"], 3);
    // ... but not once a file of someone else's is in it.
    std::fs::write(ds.join("notes.md"), "mine").expect("write");
    let (code, text) = export(&[s(&mcap), "--out", s(&ds), "--force"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("notes.md"), "{text}");
    assert_eq!(std::fs::read_to_string(ds.join("notes.md")).expect("read"), "mine");
    only(d, &["demo", "link", "thesis", "ds.txt", "ds"]);
}

#[test]
fn every_exit_code_of_the_docs_table() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let mcap = d.join("run.mcap");
    synthetic(&mcap, 2, (32, 24), |_| 1.0);
    let out = d.join("ds");
    // 2: --fps outside 1..=1000, refused where the command line is read (before ffmpeg).
    for fps in ["0", "1001", "4294967295"] {
        let (code, text) = export(&[s(&mcap), "--out", s(&out), "--fps", fps]);
        assert_eq!(code, Some(2), "--fps {fps}: {text}");
        assert!(text.contains("--fps"), "{text}");
    }
    // 2: an --out that cannot be written: under a file, and (not as root, whom permissions do
    // not stop) under a read-only folder. Refused before the recordings are read.
    let file = d.join("plain");
    std::fs::write(&file, "x").expect("write");
    let (code, text) = export(&[s(&mcap), "--out", s(&file.join("ds"))]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("plain"), "{text}");
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = d.join("ro");
        std::fs::create_dir(&ro).expect("mkdir");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).expect("chmod");
        if std::fs::write(ro.join("probe"), "x").is_err() {
            let (code, text) = export(&[s(&mcap), "--out", s(&ro.join("ds"))]);
            assert_eq!(code, Some(2), "{text}");
            assert!(text.contains("cannot write into"), "{text}");
        }
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).expect("chmod");
        std::fs::remove_dir_all(&ro).expect("rm");
    }
    // 2: an empty file; the folder made for --out's parent is gone again.
    let empty = d.join("empty.mcap");
    std::fs::write(&empty, b"").expect("write");
    let (code, text) = export(&[s(&empty), "--out", s(&d.join("new/ds"))]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("empty.mcap") && text.contains("empty (0 bytes)"), "{text}");
    // 1: ffmpeg missing (the machine's failure, not the input's).
    let o = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["export", "lerobot", s(&mcap), "--out", s(&out)])
        .env("PATH", d)
        .output()
        .expect("run hitl");
    let text = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{text}");
    assert!(text.contains("ffmpeg"), "{text}");
    // 0: done.
    let (code, text) = export(&[s(&mcap), "--out", s(&out), "--json"]);
    assert_eq!(code, Some(0), "{text}");
    only(d, &["run.mcap", "plain", "empty.mcap", "ds"]);
}
