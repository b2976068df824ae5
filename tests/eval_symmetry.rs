//! `hitl eval --json` scores up to the target's symmetry next to the paper's figures, on
//! recordings made here whose numbers are known by hand: an estimate turned 180 deg about the
//! two-planes target's symmetry axis is e_r 180 and e_r_sym 0; the same turn of a one-plane or
//! asymmetric target stays 180 (a mirror plane is no proper rotation); an OBJ target declares its
//! symmetry in a `FILE.symmetry` file next to it, and `--target-symmetry` overrides any.

use hitl_hal::{Intrinsics, Pose};
use hitl_record::{DepthImage, FrameRecord, Plane, PoseStamped, Recorder, RunMetadata};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

mod common;
use common::{hitl, num};

/// Ground truth of frame k: the target a few metres ahead, drifting and turning.
fn gt(k: usize) -> Pose {
    Isometry3::from_parts(
        Translation3::new(0.01 * k as f64, -0.02, 1.0 + 0.05 * k as f64),
        UnitQuaternion::from_euler_angles(0.1 * k as f64, 0.2, -0.05 * k as f64),
    )
}

fn turn(axis: Vector3<f64>, deg: f64) -> Pose {
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians()),
    )
}

/// Eight 16x16 frames at scale 0.01 of `target`. The estimator is off by a constant offset (a
/// 30 deg turn about the target's x and 1 mm, removed by the paper's calibration); frames 2 and
/// 5 come out turned by `twin` (in the target frame), frame 6 by `twin` and 3 deg about x.
fn write_recording(path: &Path, target: &str, twin: Pose) {
    let mut meta = RunMetadata { scale: Some(0.01), ..Default::default() };
    meta.extra.insert("target_model".into(), target.into());
    let (handle, tel) = Recorder::spawn(path, &meta).expect("recorder");
    let offset = Isometry3::translation(0.001, 0.0, 0.0) * turn(Vector3::x(), 30.0);
    for k in 0..8usize {
        let t = 1_000_000_000 + k as u64 * 100_000_000;
        let frame = FrameRecord {
            tick: k as u64 * 25,
            capture_ns: t,
            intrinsics: Intrinsics::pinhole(16, 16, 20.0, 20.0, 8.0, 8.0),
            color: Some(Plane { width: 16, height: 16, data: vec![40; 16 * 16 * 3].into() }),
            depth: Some(DepthImage::Metres(Plane {
                width: 16,
                height: 16,
                data: vec![1.0; 256].into(),
            })),
            mask: Some(Plane { width: 16, height: 16, data: vec![255; 256].into() }),
            gt_pose: Some(gt(k)),
            tf: None,
            trigger_ns: None,
            light_level: None,
        };
        assert!(tel.push_frame(frame));
        let error = match k {
            2 | 5 => twin,
            6 => twin * turn(Vector3::x(), 3.0),
            _ => Pose::identity(),
        };
        let est = gt(k) * error * offset;
        tel.push_pose_estimate(&PoseStamped { capture_ns: t, pose: est });
    }
    handle.finish().expect("recording closes");
}

fn eval(rec: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["eval", rec.to_str().expect("utf-8"), "--json"];
    args.extend_from_slice(extra);
    let out = hitl(&args);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

/// e_r per frame (scored frames), plain and up to symmetry.
fn per_frame(v: &serde_json::Value) -> Vec<(f64, f64)> {
    v["per_frame"]
        .as_array()
        .expect("per_frame")
        .iter()
        .map(|r| (num(r, "er_deg"), num(r, "er_sym_deg")))
        .collect()
}

#[test]
fn a_two_planes_twin_turned_about_its_axis_is_forgiven_only_up_to_symmetry() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("run.mcap");
    write_recording(&rec, "two-planes", turn(Vector3::z(), 180.0));
    let v = eval(&rec, &["--per-frame"]);
    assert_eq!(v["symmetry"], "two-planes:z", "{v}");
    assert_eq!(v["symmetry_source"], "built-in target two-planes", "{v}");
    let rows = per_frame(&v);
    assert_eq!(rows.len(), 8);
    for (k, (er, sym)) in rows.iter().enumerate() {
        let (want, want_sym) = match k {
            2 | 5 => (180.0, 0.0),
            // A half turn about z and 3 deg about x is still a half turn (about a tilted axis).
            6 => (180.0, 3.0),
            _ => (0.0, 0.0),
        };
        assert!((er - want).abs() < 1e-6, "frame {k}: e_r {er}, want {want}");
        assert!((sym - want_sym).abs() < 1e-6, "frame {k}: e_r_sym {sym}, want {want_sym}");
    }
    // The paper's figures are untouched: mean 3 x 180 / 8, median 0.
    assert!((num(&v, "mean_er_deg") - 540.0 / 8.0).abs() < 1e-6, "{v}");
    assert!(num(&v, "median_er_deg").abs() < 1e-6, "{v}");
    assert!((num(&v, "mean_er_sym_deg") - 3.0 / 8.0).abs() < 1e-6, "{v}");
    assert!(num(&v, "median_er_sym_deg").abs() < 1e-6, "{v}");
    assert!(num(&v, "mean_er_sym_deg") <= num(&v, "mean_er_deg"));
    // The axis passes through the target's origin: the twin's translation is the truth's.
    assert!((num(&v, "mean_et_sym_m") - num(&v, "mean_et_m")).abs() < 1e-12, "{v}");
    assert!(num(&v, "mean_et_m") < 1e-9, "{v}");

    // The text output names the symmetry and shows both.
    let out = hitl(&["eval", rec.to_str().expect("utf-8")]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("up to the target's symmetry (two-planes:z"), "{text}");
    assert!(text.contains("e_r deg:    mean 67.5"), "{text}");

    // The report shows both, in its summary and its page.
    let out_dir = dir.path().join("report");
    let out = hitl(&[
        "report",
        rec.to_str().expect("utf-8"),
        "--json",
        "--contact-frames",
        "0",
        "--out",
        out_dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_slice(&out.stdout).expect("summary JSON");
    let m = &s["pose_metrics"];
    assert!((num(m, "mean_er_deg") - 67.5).abs() < 1e-6, "{s}");
    assert!((num(m, "mean_er_sym_deg") - 3.0 / 8.0).abs() < 1e-6, "{s}");
    let page = std::fs::read_to_string(out_dir.join("index.html")).expect("index.html");
    assert!(page.contains("up to symmetry (two-planes:z)"), "{page}");
    assert!(page.contains("e_r mean 67.50&deg;") && page.contains("e_r mean 0.38&deg;"), "{page}");
}

#[test]
fn mirror_planes_alone_forgive_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    for target in ["one-plane", "asymmetric"] {
        let rec = dir.path().join(format!("{target}.mcap"));
        write_recording(&rec, target, turn(Vector3::z(), 180.0));
        let v = eval(&rec, &[]);
        let want = if target == "one-plane" { "one-plane" } else { "none" };
        assert_eq!(v["symmetry"], want, "{v}");
        for k in ["mean_er", "median_er", "std_er"] {
            assert_eq!(v[format!("{k}_deg")], v[format!("{k}_sym_deg")], "{target} {k}: {v}");
        }
        assert!((num(&v, "mean_er_sym_deg") - 540.0 / 8.0).abs() < 1e-6, "{v}");
    }
}

#[test]
fn an_obj_declares_its_symmetry_next_to_it_and_the_flag_overrides() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A square plate, 4-fold about z through its middle (the file's origin is a corner).
    let obj = dir.path().join("plate.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 1 1 0.2\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n",
    )
    .expect("write");
    let rec = dir.path().join("run.mcap");
    write_recording(&rec, obj.to_str().expect("utf-8"), turn(Vector3::z(), 90.0));

    // Nothing declared: the symmetric figures are the paper's.
    let v = eval(&rec, &[]);
    assert_eq!(v["symmetry"], "none", "{v}");
    assert!(v["symmetry_source"].as_str().expect("source").contains("none declared"), "{v}");
    assert!((num(&v, "mean_er_sym_deg") - num(&v, "mean_er_deg")).abs() < 1e-12, "{v}");
    assert!((num(&v, "mean_er_deg") - (90.0 * 2.0 + 90.05) / 8.0).abs() < 0.1, "{v}");

    std::fs::write(dir.path().join("plate.obj.symmetry"), "# square plate\n4-fold:z\n")
        .expect("write");
    let v = eval(&rec, &["--per-frame"]);
    assert_eq!(v["symmetry"], "4-fold:z", "{v}");
    assert!(v["symmetry_source"].as_str().expect("source").ends_with("plate.obj.symmetry"));
    let rows = per_frame(&v);
    assert!(rows[2].1 < 1e-6 && rows[5].1 < 1e-6, "{rows:?}");
    assert!((rows[6].1 - 3.0).abs() < 1e-6, "{rows:?}");
    assert!((num(&v, "mean_er_sym_deg") - 3.0 / 8.0).abs() < 1e-6, "{v}");

    // The flag wins over the file: a 2-fold turn does not forgive a quarter turn.
    let v = eval(&rec, &["--target-symmetry", "two-planes:z"]);
    assert_eq!(v["symmetry_source"], "--target-symmetry");
    assert!((num(&v, "mean_er_sym_deg") - num(&v, "mean_er_deg")).abs() < 1e-9, "{v}");
    let v = eval(&rec, &["--target-symmetry", "revolution:z"]);
    assert!((num(&v, "mean_er_sym_deg") - 3.0 / 8.0).abs() < 1e-6, "{v}");

    // A bad declaration is refused, naming it, with exit 2.
    let out = hitl(&["eval", rec.to_str().expect("utf-8"), "--target-symmetry", "3-fold:w"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--target-symmetry"));
    std::fs::write(dir.path().join("plate.obj.symmetry"), "five-fold\n").expect("write");
    let out = hitl(&["eval", rec.to_str().expect("utf-8"), "--json"]);
    assert_eq!(out.status.code(), Some(0), "an unreadable declaration only warns");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("plate.obj.symmetry") && err.contains("five-fold"), "{err}");
}

#[test]
fn the_detailed_spacecraft_score_up_to_their_declared_group_and_never_above_the_paper() {
    // The RQ3 targets: each detailed two-planes spacecraft forgives the half turn about its own
    // axis only; the others forgive nothing. The symmetric mean is never above the paper's.
    let cases = [
        ("sat3-two-planes", "two-planes:z", Vector3::z(), true),
        ("sat4-two-planes-slender", "two-planes:z", Vector3::z(), true),
        ("sat5-two-planes-y", "two-planes:y", Vector3::y(), true),
        ("sat5-two-planes-y", "two-planes:y", Vector3::z(), false),
        ("sat1-none", "none", Vector3::z(), false),
        ("sat2-one-plane", "one-plane", Vector3::z(), false),
    ];
    let dir = tempfile::tempdir().expect("tempdir");
    for (i, (target, group, axis, forgiven)) in cases.into_iter().enumerate() {
        let rec = dir.path().join(format!("run-{i}.mcap"));
        write_recording(&rec, target, turn(axis, 180.0));
        let v = eval(&rec, &[]);
        assert_eq!(v["symmetry"], group, "{target}: {v}");
        let (er, sym) = (num(&v, "mean_er_deg"), num(&v, "mean_er_sym_deg"));
        assert!((er - 540.0 / 8.0).abs() < 1e-6, "{target}: the paper's mean {er}");
        assert!(sym <= er + 1e-12, "{target}: sym {sym} above the paper's {er}");
        if forgiven {
            assert!((sym - 3.0 / 8.0).abs() < 1e-6, "{target} about {axis:?}: sym {sym}");
        } else {
            // A half turn about another axis stays a half turn, up to the group too (frame 6's
            // extra 3 deg may be taken up by the group's half turn: 177 deg).
            assert!(sym > 60.0, "{target} about {axis:?}: sym {sym} forgives a non-symmetry");
        }
    }
}
