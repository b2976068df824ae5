//! The report's contact sheet on synthetic recordings: which captures it shows, that the
//! ground-truth outline is the recorded mask's boundary (or the model's at the ground-truth pose
//! without a mask), that an estimate N pixels off is outlined N pixels away, that large frames
//! are shrunk, and what index.html says.

mod common;

use common::meta;
use hitl_hal::{Intrinsics, Pose};
use hitl_record::report::contact::{rasterize, Silhouette, ESTIMATE_COLOUR, GROUND_TRUTH_COLOUR};
use hitl_record::report::{
    write_report, write_report_with, ContactOptions, ReportOptions, TargetMesh,
};
use hitl_record::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

const GREY: u8 = 100;

/// A 0.3 m square facing the camera (target frame z = 0).
fn square() -> TargetMesh {
    let a = 0.15;
    TargetMesh {
        vertices: vec![[-a, -a, 0.0], [a, -a, 0.0], [a, a, 0.0], [-a, a, 0.0]],
        faces: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// f = 80 px at 96x64 (scaled with the size): the square at 1 m spans u in [35.5, 59.5] and v in
/// [19.5, 43.5] at 96x64, pixels 36..=59 x 20..=43.
fn intrinsics(w: u32, h: u32) -> Intrinsics {
    let s = f64::from(w) / 96.0;
    Intrinsics {
        width: w,
        height: h,
        fx: 80.0 * s,
        fy: 80.0 * s,
        cx: 47.5 * s,
        cy: 31.5 * s,
        distortion: Default::default(),
    }
}

fn gt_pose() -> Pose {
    Pose::translation(0.0, 0.0, 1.0)
}

/// The estimate `px` pixels to the right of the ground truth (the square is at 1 m, f = 80).
fn shifted(px: f64) -> Pose {
    Pose::translation(px / 80.0, 0.0, 1.0)
}

fn frame(k: u64, t: u64, w: u32, h: u32, with_mask: bool) -> FrameRecord {
    let n = (w * h) as usize;
    let mask = rasterize(&square(), &gt_pose(), &intrinsics(w, h));
    FrameRecord {
        tick: k,
        capture_ns: t,
        intrinsics: intrinsics(w, h),
        color: Some(Plane { width: w, height: h, data: vec![GREY; n * 3].into() }),
        depth: Some(DepthImage::Metres(Plane { width: w, height: h, data: vec![1.0; n].into() })),
        mask: with_mask.then(|| Plane {
            width: w,
            height: h,
            data: mask.inside.iter().map(|&v| if v { 255 } else { 0 }).collect::<Vec<_>>().into(),
        }),
        gt_pose: Some(gt_pose()),
        tf: None,
        trigger_ns: Some(t - 1_000_000),
        light_level: None,
    }
}

/// Record `frames` (with their estimates) into `path`.
fn record(path: &Path, frames: Vec<(FrameRecord, Option<Pose>)>) {
    let (handle, tel) = Recorder::spawn(path, &meta()).expect("spawn");
    for (f, est) in frames {
        let t = f.capture_ns;
        let give_up = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while !tel.frame_queue_has_room() && std::time::Instant::now() < give_up {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert!(tel.push_frame(f), "frame at {t} not queued");
        if let Some(pose) = est {
            tel.push_pose_estimate(&PoseStamped { capture_ns: t, pose });
        }
    }
    handle.finish().expect("finish");
}

struct Png {
    width: u32,
    height: u32,
    rgb: Vec<u8>,
}

impl Png {
    fn read(path: &Path) -> Png {
        let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut r = png::Decoder::new(std::io::BufReader::new(file)).read_info().expect("png");
        let mut buf = vec![0; r.output_buffer_size().expect("size")];
        let info = r.next_frame(&mut buf).expect("frame");
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        Png { width: info.width, height: info.height, rgb: buf }
    }

    /// Pixels of exactly this colour.
    fn coloured(&self, c: [u8; 3]) -> BTreeSet<(u32, u32)> {
        (0..self.height)
            .flat_map(|y| (0..self.width).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let i = ((y * self.width + x) * 3) as usize;
                self.rgb[i..i + 3] == c
            })
            .collect()
    }
}

fn pixels(s: &Silhouette) -> BTreeSet<(u32, u32)> {
    (0..s.height)
        .flat_map(|y| (0..s.width).map(move |x| (x, y)))
        .filter(|&(x, y)| s.get(x, y))
        .collect()
}

fn shift(set: &BTreeSet<(u32, u32)>, dx: u32) -> BTreeSet<(u32, u32)> {
    set.iter().map(|&(x, y)| (x + dx, y)).collect()
}

#[test]
fn outlines_lie_on_the_mask_boundary_and_an_offset_estimate_is_drawn_that_far_away() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    const N: u32 = 5;
    // Ten captures, 0.1 s apart; odd ones without a mask; estimates at 0 and 6 only.
    let frames = (0..10u64)
        .map(|k| {
            let t = 2_000_000_000 + k * 100_000_000;
            let est = (k % 6 == 0).then(|| shifted(f64::from(N)));
            (frame(k, t, 96, 64, k % 2 == 0), est)
        })
        .collect();
    record(&path, frames);
    let out = dir.path().join("report");
    let model = |_: &BTreeMap<String, String>| Ok(square());
    let opts = ReportOptions {
        contact: ContactOptions { frames: 4, max_width: 480, model: Some(&model), zoom: None },
        pose_metrics: None,
    };
    let r = write_report_with(&path, Some(&out), &opts).expect("report");

    let sheet = r.summary.contact_sheet.as_ref().expect("sheet");
    assert_eq!(sheet.captures, 10);
    let shown: Vec<usize> = sheet.frames.iter().map(|f| f.capture).collect();
    assert_eq!(shown, vec![0, 3, 6, 9]);
    assert!(sheet.notes.is_empty(), "{:?}", sheet.notes);

    let mask = rasterize(&square(), &gt_pose(), &intrinsics(96, 64));
    let boundary = pixels(&mask.outline());
    assert_eq!(boundary.len(), 2 * 24 + 2 * 22, "a 24x24 square's ring");
    for f in &sheet.frames {
        let png = Png::read(&out.join(&f.file));
        assert_eq!((png.width, png.height, f.width, f.height), (96, 64, 96, 64));
        let gt = png.coloured(GROUND_TRUTH_COLOUR);
        let est = png.coloured(ESTIMATE_COLOUR);
        assert!(
            gt.is_subset(&boundary),
            "capture {}: ground truth off the mask's boundary",
            f.capture
        );
        assert_eq!(
            png.coloured([GREY; 3]).len() + gt.len() + est.len(),
            96 * 64,
            "only outlines drawn"
        );
        if f.capture % 6 == 0 {
            // The estimate's outline is the mask's, N pixels to the right; where the two meet
            // (top and bottom rows) the estimate's is drawn.
            assert!(f.estimate);
            assert_eq!(est, shift(&boundary, N), "capture {}", f.capture);
            assert_eq!(gt, &boundary - &est, "capture {}", f.capture);
            assert!((f.et_lab_mm.expect("e_t") - 1000.0 * f64::from(N) / 80.0).abs() < 1e-9);
            assert!((f.et_m.expect("real e_t") - 0.0625 / 0.01).abs() < 1e-9, "scale 0.01");
            assert!(f.er_deg.expect("e_r").abs() < 1e-6);
            let iou = f.estimate_iou.expect("iou");
            assert!((iou - 19.0 / 29.0).abs() < 1e-12, "{iou}");
        } else {
            assert!(!f.estimate && f.et_lab_mm.is_none() && est.is_empty());
            assert_eq!(gt, boundary, "capture {}", f.capture);
        }
        // Even captures recorded a mask; odd ones fall back to the model at the ground truth.
        let want = if f.capture % 2 == 0 { "mask" } else { "model" };
        assert_eq!(serde_json::to_value(f.ground_truth).expect("json"), want);
        if f.capture % 2 == 0 {
            assert_eq!(f.model_mask_iou, Some(1.0));
        }
    }
    assert!((sheet.frames[1].t_s - 0.3).abs() < 1e-9, "{}", sheet.frames[1].t_s);

    let html = std::fs::read_to_string(out.join("index.html")).expect("html");
    for needle in [
        "Contact sheet",
        "contact/000.png",
        "contact/009.png",
        "no estimate",
        "#00ff00",
        "#ff00ff",
        "e_t 6.250 m",
        "ground truth from the model",
    ] {
        assert!(html.contains(needle), "index.html lacks {needle:?}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("read"))
            .expect("json");
    assert_eq!(json["contact_sheet"]["frames"][2]["file"], "contact/006.png");
    assert!(r.files.iter().any(|f| f.ends_with("contact/003.png")));

    // A second report into the same folder with fewer frames leaves no stale PNG behind.
    let opts = ReportOptions { contact: ContactOptions { frames: 2, ..opts.contact }, ..opts };
    write_report_with(&path, Some(&out), &opts).expect("report again");
    let mut left: Vec<String> = std::fs::read_dir(out.join("contact"))
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["000.png", "009.png"]);
}

#[test]
fn a_large_frame_is_shrunk_and_its_outlines_follow() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    // 1280x800 with an estimate 15 source pixels off: 5.625 sheet pixels at 480 wide.
    let (w, h) = (1280, 800);
    let est = Pose::translation(15.0 / (80.0 * 1280.0 / 96.0), 0.0, 1.0);
    record(&path, vec![(frame(0, 3_000_000_000, w, h, true), Some(est))]);
    let out = dir.path().join("report");
    let model = |_: &BTreeMap<String, String>| Ok(square());
    let opts = ReportOptions {
        contact: ContactOptions { model: Some(&model), ..Default::default() },
        ..Default::default()
    };
    let r = write_report_with(&path, Some(&out), &opts).expect("report");
    let f = &r.summary.contact_sheet.as_ref().expect("sheet").frames[0];
    let png = Png::read(&out.join(&f.file));
    assert_eq!((png.width, png.height), (480, 300));
    // The square spans source x 474..=793 (320 pixels), sheet x 178..=297 (120 pixels); the
    // estimate's left edge is at 177.19 + 5.625 sheet pixels.
    let gt = png.coloured(GROUND_TRUTH_COLOUR);
    let est = png.coloured(ESTIMATE_COLOUR);
    let left = |s: &BTreeSet<(u32, u32)>, y: u32| s.iter().filter(|p| p.1 == y).map(|p| p.0).min();
    assert_eq!(left(&gt, 150), Some(178), "ground truth's left edge");
    assert_eq!(left(&est, 150), Some(183), "estimate's left edge, 5.6 px right");
    assert!(gt.len() > 200 && est.len() > 400, "{} {}", gt.len(), est.len());
    let iou = f.model_mask_iou.expect("iou");
    assert!(iou > 0.98, "model vs shrunk mask {iou}");
}

#[test]
fn without_a_model_the_recorded_mask_is_drawn_and_without_frames_a_line_says_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    record(&path, vec![(frame(0, 1_000_000_000, 96, 64, true), Some(shifted(3.0)))]);
    let out = dir.path().join("report");
    let r = write_report(&path, Some(&out)).expect("report");
    let sheet = r.summary.contact_sheet.as_ref().expect("sheet");
    let f = &sheet.frames[0];
    assert!(
        !f.estimate && f.et_lab_mm.is_some(),
        "errors known, nothing to draw the estimate with"
    );
    assert!(sheet.notes.iter().any(|n| n.contains("no target model")), "{:?}", sheet.notes);
    let png = Png::read(&out.join(&f.file));
    let mask = rasterize(&square(), &gt_pose(), &intrinsics(96, 64));
    assert_eq!(png.coloured(GROUND_TRUTH_COLOUR), pixels(&mask.outline()));
    assert!(png.coloured(ESTIMATE_COLOUR).is_empty());

    // A run recorded without a camera: no sheet, a line saying so.
    let bare = dir.path().join("bare.mcap");
    let (handle, tel) = Recorder::spawn(&bare, &meta()).expect("spawn");
    tel.push_light(&LightMsg { t_ns: 1, level: 0.5 });
    handle.finish().expect("finish");
    let out = dir.path().join("bare_report");
    let r = write_report(&bare, Some(&out)).expect("report");
    let sheet = r.summary.contact_sheet.as_ref().expect("sheet");
    assert!(sheet.frames.is_empty() && sheet.captures == 0);
    let html = std::fs::read_to_string(out.join("index.html")).expect("html");
    assert!(html.contains("no camera frames (a run without a camera"), "{html}");
    assert!(!out.join("contact").exists());
}
