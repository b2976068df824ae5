//! Captures end to end on the stub: a planned fly-around played with the simulated camera records
//! exactly one colour, depth and mask image and one ground-truth pose per capture waypoint, and
//! the ground truth (from FK and the lab, computed by the controller) agrees with what the
//! renderer drew: the target model's vertices projected through it and the intrinsics bound the
//! rendered mask, which covers most of their box.

use hitl_record::reader::{decode_image, read_recording, visit};
use hitl_trajectories::npz;
use std::collections::BTreeMap;
use std::ops::ControlFlow;

mod common;
use common::{hitl, plan_flyaround, SIM_CAPTURE_RUN, SIM_CLOCK};

#[test]
fn one_image_set_and_one_ground_truth_per_capture_and_the_truth_lands_on_the_mask() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("fly.npz");
    let mcap = dir.path().join("run.mcap");
    let (t, m) = (traj.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    plan_flyaround(&traj, "10", "25");
    let zstd = ["--record-compression", "zstd"];
    let args = [&["run", t, "--record", m][..], &zstd, &SIM_CAPTURE_RUN, &SIM_CLOCK].concat();
    let run = hitl(&args);
    let out =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert_eq!(run.status.code(), Some(0), "{out}");

    // Every chunk is compressed as asked.
    let bytes = std::fs::read(&mcap).expect("read the recording");
    let summary = mcap::Summary::read(&bytes).expect("summary").expect("a summary section");
    assert!(!summary.chunk_indexes.is_empty());
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == "zstd"), "not all zstd");

    let captures = npz::load(&traj).expect("plan").trajectory.capture_count() as u64;
    assert!(captures >= 5, "{captures} captures");
    let rec = read_recording(&mcap).expect("recording");
    for topic in [
        "/camera/color",
        "/camera/depth",
        "/camera/mask",
        "/camera/calibration",
        "/camera/sync",
        "/pose/gt",
    ] {
        assert_eq!(
            rec.topic_counts.get(topic).copied(),
            Some(captures),
            "{topic}: {:?}",
            rec.topic_counts
        );
    }

    // Every frame's sync record: exposure after its trigger, the difference as written, and the
    // largest one the one the run summary printed.
    let mut ticks: Vec<u64> = rec.capture_sync.iter().map(|s| s.tick).collect();
    ticks.dedup();
    assert_eq!(ticks.len() as u64, captures, "one sync record per capture");
    for s in &rec.capture_sync {
        assert!(s.exposure_ns >= s.trigger_ns, "{s:?}");
        assert_eq!((s.exposure_ns - s.trigger_ns) as i64, s.sync_error_ns);
    }
    let max_ms =
        rec.capture_sync.iter().map(|s| s.sync_error_ns.abs()).max().unwrap_or(0) as f64 / 1e6;
    assert!(out.contains(&format!("max {max_ms:.2} ms")), "max {max_ms:.2} ms not in: {out}");

    // WFOV at 320x256: f = 1545 * 320 / 1280, principal point (640, 512) of 1280x1024 scaled
    // with the pixel centres (hitl_hal::Intrinsics::scaled): (640.5 / 4 - 0.5, 512.5 / 4 - 0.5).
    let (f, cx, cy) = (1545.0 * 320.0 / 1280.0, 159.625, 127.625);
    let mut masks: BTreeMap<u64, (u32, u32, u32, Vec<u8>)> = BTreeMap::new();
    visit(
        &mcap,
        |msg| {
            if msg.topic == "/camera/mask" {
                let img = decode_image(msg.data).expect("mask decodes");
                masks.insert(msg.log_time, (img.width, img.height, img.step, img.data.to_vec()));
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .expect("visit");
    // The target's known points: the model's vertices at the run's scale, in the target frame.
    let scale: f64 = rec.metadata["run"]["scale"].parse().expect("run scale");
    let model = hitl_perception::TargetModel::from_spec("asymmetric").expect("model");
    let (vertices, _) = model.lab_mesh(scale).expect("mesh").to_f32();
    let mut checked = 0;
    for gt in &rec.pose_gt {
        let (w, h, step, data) =
            masks.get(&gt.capture_ns).expect("a mask with the pose's timestamp");
        // Bounding box of the rendered mask.
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for v in 0..*h as usize {
            for u in 0..*w as usize {
                if data[v * *step as usize + u] > 0 {
                    lo = [lo[0].min(u as i64), lo[1].min(v as i64)];
                    hi = [hi[0].max(u as i64), hi[1].max(v as i64)];
                }
            }
        }
        assert!(lo[0] <= hi[0], "an empty mask at {}", gt.capture_ns);
        // Bounding box of the vertices projected through the ground truth and the intrinsics.
        let (mut plo, mut phi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in &vertices {
            let q = nalgebra::Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            let [x, y, z]: [f64; 3] = gt.pose.transform_point(&q).coords.into();
            assert!(z > 0.0, "the target is in front of the camera");
            let (u, v) = (f * x / z + cx, f * y / z + cy);
            plo = [plo[0].min(u), plo[1].min(v)];
            phi = [phi[0].max(u), phi[1].max(v)];
        }
        // Every masked pixel lies inside the projected box (1 px for rasterisation), and the two
        // boxes overlap by at least 40 % (parts thinner than a pixel, like a boom, can miss every
        // ray, so the mask may be smaller than the model's silhouette).
        for k in 0..2 {
            let (l, h) = (lo[k] as f64, hi[k] as f64);
            assert!(
                l >= plo[k] - 1.0 && h <= phi[k] + 1.0,
                "mask box {lo:?}-{hi:?} leaves the projected box {plo:?}-{phi:?}"
            );
        }
        let area = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0] + 1.0) * (b[1] - a[1] + 1.0);
        let mask_area = area([lo[0] as f64, lo[1] as f64], [hi[0] as f64, hi[1] as f64]);
        let iou = mask_area / area(plo, phi);
        assert!(iou >= 0.4, "mask box {lo:?}-{hi:?} covers {iou:.2} of {plo:?}-{phi:?}");
        checked += 1;
    }
    assert_eq!(checked, captures);
}
