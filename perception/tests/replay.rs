//! A recording written by hitl-record is read back into frames and scored: the offline path of
//! `hitl eval --backend icp`.
#![allow(clippy::unwrap_used)]

use hitl_perception::icp::{IcpConfig, IcpTracker};
use hitl_perception::metrics::{evaluate, PosePair};
use hitl_perception::replay::replay_frames;
use hitl_perception::testing::{intrinsics_hfov, look_pose, render};
use hitl_perception::{PoseEstimator, TargetModel};
use hitl_record::{DepthImage, FrameRecord, Plane, Recorder, RunMetadata};

#[test]
fn recorded_frames_replay_through_the_tracker() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let scale = 0.05;
    let meta = RunMetadata { scale: Some(scale), ..Default::default() };
    let (handle, tel) = Recorder::spawn(&path, &meta).unwrap();
    let k = intrinsics_hfov(96, 72, 36.5);
    let mesh = TargetModel::from_spec("asymmetric").unwrap().lab_mesh(scale).unwrap();
    let mut gts = Vec::new();
    for i in 0..5u64 {
        let gt = look_pose(0.5, 0.3, -0.2, 0.8 + 0.03 * i as f64);
        let f = render(&mesh, &gt, &k, 1_000_000 * (i + 1));
        gts.push((f.timestamp_ns, gt));
        let plane = |data| Plane { width: k.width, height: k.height, data };
        let rec = FrameRecord {
            tick: i,
            capture_ns: f.timestamp_ns,
            intrinsics: k,
            color: Some(plane(f.color.clone())),
            depth: Some(DepthImage::Metres(Plane {
                width: k.width,
                height: k.height,
                data: f.depth_m.clone(),
            })),
            mask: f.mask.clone().map(plane),
            gt_pose: Some(gt),
            tf: None,
            trigger_ns: None,
            light_level: None,
        };
        while !tel.frame_queue_has_room() {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        assert!(tel.push_frame(rec));
    }
    handle.finish().unwrap();

    let mut tracker = IcpTracker::new(&mesh, IcpConfig::default()).unwrap();
    let mut pairs = Vec::new();
    let summary = replay_frames(&path, |f| {
        let gt = gts.iter().find(|(t, _)| *t == f.timestamp_ns).unwrap().1;
        assert!(f.mask.is_some() && f.color.len() == (3 * k.width * k.height) as usize);
        let est = tracker.estimate(&f).unwrap().pose;
        pairs.push(PosePair { timestamp_ns: f.timestamp_ns, gt, est });
    })
    .unwrap();
    assert_eq!(summary.frames, 5);
    assert_eq!(summary.skipped, 0);
    let ts: Vec<u64> = pairs.iter().map(|p| p.timestamp_ns).collect();
    assert_eq!(ts, gts.iter().map(|g| g.0).collect::<Vec<_>>(), "file order");
    let m = evaluate(&pairs, scale).unwrap();
    assert_eq!(m.failures, 0);
    // 10 m real range: far inside the 1 % goal.
    assert!(m.mean_et_m < 0.02 && m.mean_er_deg < 0.5, "{:?}", m.to_json());
}
