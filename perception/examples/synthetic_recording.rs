//! Writes a small synthetic recording (rendered frames of a built-in target, ground truth and an
//! estimate 2 mm off) for trying `hitl eval`:
//! `cargo run -p hitl-perception --example synthetic_recording -- OUT.mcap`.

use hitl_perception::testing::{intrinsics_hfov, look_pose, render};
use hitl_perception::TargetModel;
use hitl_record::{DepthImage, FrameRecord, Plane, PoseStamped, Recorder, RunMetadata};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).ok_or("usage: synthetic_recording OUT.mcap")?;
    let scale = 0.05;
    let mut meta = RunMetadata { scale: Some(scale), ..Default::default() };
    meta.extra.insert("target_model".into(), "one-plane".into());
    let (handle, tel) = Recorder::spawn(&out, &meta)?;
    let k = intrinsics_hfov(128, 96, 36.5);
    let mesh = TargetModel::from_spec("one-plane")?.lab_mesh(scale)?;
    for i in 0..20u64 {
        let gt = look_pose(0.5, 0.3, -0.2, 0.8 + 0.02 * i as f64);
        let f = render(&mesh, &gt, &k, 1_000_000 * (i + 1));
        let plane = |data| Plane { width: k.width, height: k.height, data };
        while !tel.frame_queue_has_room() {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        tel.push_frame(FrameRecord {
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
        });
        let mut est = gt;
        if i > 0 {
            est.translation.x += 0.002;
        }
        tel.push_pose_estimate(&PoseStamped { capture_ns: f.timestamp_ns, pose: est });
    }
    handle.finish()?;
    Ok(())
}
