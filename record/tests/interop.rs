//! A short synthetic run read back by the official Python MCAP reader and by our own reader.

mod common;

use common::*;
use hitl_hal::Pose;
use hitl_record::reader::read_recording;
use hitl_record::*;

const TICKS: u64 = 200;
const FRAMES: u64 = 6;
const T0: u64 = 5_000_000_000;

fn write_run(path: &std::path::Path, cfg: RecorderConfig) -> RecordSummary {
    let (handle, tel) = Recorder::spawn_with(path, &meta(), cfg).expect("spawn");
    let health = handle.health();
    for k in 0..TICKS {
        let t = T0 + k * 4_000_000;
        let phase = if k < 20 { Phase::Approach } else { Phase::Playback };
        let mut q = [0.0; 7];
        q[0] = k as f64 * 0.001;
        tel.push_setpoint(&SetpointMsg { tick: k, t_ns: t, phase, q, qd: [0.25; 7] });
        let mut qm = q;
        qm[0] -= 0.002;
        tel.push_state(&ArmStateMsg {
            t_ns: t + 1_000_000,
            q: qm,
            state: 1,
            mode: 1,
            error_code: 0,
            warn_code: 0,
        });
        tel.push_timing(&TimingMsg {
            tick: k,
            t_ns: t,
            wake_late_ns: (k % 10) as i64 * 1000,
            tick_ns: 15_000,
            overrun: k == 50,
        });
        if k.is_multiple_of(40) {
            tel.push_light(&LightMsg { t_ns: t, level: 0.5 });
        }
        if k.is_multiple_of(30) && k / 30 < FRAMES {
            let fk = k / 30;
            assert!(tel.push_frame(frame(fk, t, true)));
            let mut est = frame(fk, t, true).gt_pose.unwrap_or_else(Pose::identity);
            est.translation.vector[2] += 0.004;
            tel.push_pose_estimate(&PoseStamped { capture_ns: t, pose: est });
        }
        if k == 100 {
            tel.push_event(SafetyEventMsg::numeric(
                t,
                EventKind::Deviation,
                k,
                Some(2),
                0.05,
                0.02,
            ));
            tel.push_event(SafetyEventMsg::text(t, EventKind::StopStarted, "deviation trip"));
        }
        // Give the recorder a chance to drain (the queues hold all of it anyway).
        if k.is_multiple_of(50) {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }
    assert!(!health.is_failed());
    let s = handle.finish().expect("finish");
    assert!(health.is_closed());
    s
}

#[test]
fn synthetic_run_reads_in_python_and_rust() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let s = write_run(&path, RecorderConfig::default());
    assert_eq!(s.written[topics::SETPOINT], TICKS);
    assert_eq!(s.written[topics::DEPTH], FRAMES);
    assert_eq!(s.dropped.values().sum::<u64>(), 0);

    // Pixels: a hole (3), ordinary ones, the last.
    let pixels = [0usize, 3, 5, 64, 127];
    let v = python_read(&path, &pixels);
    assert_eq!(v["complete"], true, "{v}");
    assert!(v["error"].is_null(), "{v}");
    for t in [
        "/arm/setpoint",
        "/arm/state",
        "/loop/timing",
        "/camera/color",
        "/camera/depth",
        "/camera/mask",
        "/camera/calibration",
        "/camera/sync",
        "/tf",
        "/pose/gt",
        "/pose/estimate",
        "/light/state",
        "/safety/event",
    ] {
        assert!(
            v["topics"].as_array().is_some_and(|a| a.iter().any(|x| x == t)),
            "topic {t} missing: {}",
            v["topics"]
        );
    }
    assert_eq!(count(&v, "/arm/setpoint"), TICKS);
    assert_eq!(count(&v, "/arm/state"), TICKS);
    assert_eq!(count(&v, "/loop/timing"), TICKS);
    assert_eq!(count(&v, "/light/state"), 5);
    assert_eq!(count(&v, "/safety/event"), 2);
    for t in ["/camera/color", "/camera/depth", "/camera/mask", "/camera/calibration"] {
        assert_eq!(count(&v, t), FRAMES, "{t}");
    }
    assert_eq!(count(&v, "/tf"), FRAMES);
    assert_eq!(count(&v, "/camera/sync"), FRAMES);
    let sync = &v["samples"]["/camera/sync"];
    assert_eq!(sync["tick"], 0);
    assert_eq!(sync["exposure_ns"].as_u64(), Some(T0));
    assert_eq!(sync["trigger_ns"].as_u64(), Some(T0 - 2_000_000));
    assert_eq!(sync["sync_error_ns"], 2_000_000);
    assert_eq!(count(&v, "/pose/gt"), FRAMES);
    assert_eq!(count(&v, "/pose/estimate"), FRAMES);
    assert_eq!(v["encodings"]["/camera/depth"][2], "foxglove.RawImage");
    assert_eq!(v["encodings"]["/tf"][2], "foxglove.FrameTransforms");
    assert_eq!(v["encodings"]["/pose/gt"][2], "foxglove.PoseInFrame");
    assert_eq!(v["encodings"]["/camera/calibration"][2], "foxglove.CameraCalibration");
    assert_eq!(v["encodings"]["/arm/setpoint"][0], "json");
    assert_eq!(v["encodings"]["/arm/setpoint"][1], "jsonschema");

    // The first depth image decodes to the values written.
    let d = &v["depth"];
    assert_eq!(d["encoding"], "32FC1");
    assert_eq!(d["width"], W);
    assert_eq!(d["height"], H);
    assert_eq!(d["stamp_ns"].as_u64(), Some(T0));
    for (n, &i) in pixels.iter().enumerate() {
        let got = d["pixels_m"][n].as_f64().unwrap_or(f64::NAN);
        assert!((got - f64::from(depth_value(0, i))).abs() < 1e-6, "pixel {i}: {got}");
    }
    let sum: f64 = (0..(W * H) as usize).map(|i| f64::from(depth_value(0, i))).sum();
    assert!((d["sum_m"].as_f64().unwrap_or(0.0) - sum).abs() < 1e-3);

    // Ground truth and estimate of one frame share its capture time.
    assert_eq!(v["samples"]["/pose/gt"]["stamp_ns"].as_u64(), Some(T0));
    assert_eq!(v["samples"]["/pose/estimate"]["stamp_ns"].as_u64(), Some(T0));
    assert_eq!(v["samples"]["/pose/gt"]["frame_id"], "camera");
    assert_eq!(v["samples"]["/tf"][0][1], "flange");
    assert_eq!(v["samples"]["/camera/calibration"]["K"][0], 20.0);
    assert_eq!(v["samples"]["/arm/setpoint"]["phase"], "approach");
    assert_eq!(v["samples"]["/arm/setpoint#last"]["phase"], "playback");
    assert_eq!(v["samples"]["/safety/event"]["kind"], "deviation");
    assert_eq!(v["samples"]["/safety/event#last"]["detail"], "deviation trip");
    assert_eq!(v["metadata"]["run"]["trajectory_sha256"], "ab".repeat(32));
    assert_eq!(v["metadata"]["run"]["scale"], "0.01");
    assert!(v["metadata"]["recorder_stats"]["written"].is_string());

    // Our reader agrees.
    let rec = read_recording(&path).expect("read");
    let end = rec.end.clone().expect("end");
    assert!(end.complete && end.truncated.is_none());
    assert_eq!(rec.setpoints.len() as u64, TICKS);
    assert_eq!(rec.setpoints[0].phase, Phase::Approach);
    assert_eq!(rec.setpoints[150].q[0], 0.15);
    assert_eq!(rec.states.len() as u64, TICKS);
    assert_eq!(rec.timing.iter().filter(|t| t.overrun).count(), 1);
    assert_eq!(rec.tf.len() as u64, FRAMES);
    assert_eq!(rec.capture_sync.len() as u64, FRAMES);
    assert_eq!(rec.capture_sync[1].tick, 10);
    assert_eq!(rec.capture_sync[1].sync_error_ns, 2_001_000);
    assert_eq!(
        rec.capture_sync[1].exposure_ns - rec.capture_sync[1].trigger_ns,
        rec.capture_sync[1].sync_error_ns as u64
    );
    assert_eq!(rec.tf[1], tf_at(T0 + 30 * 4_000_000, 1));
    assert_eq!(rec.pose_gt.len() as u64, FRAMES);
    assert_eq!(rec.pose_gt[2].capture_ns, rec.pose_estimate[2].capture_ns);
    assert_eq!(rec.events[0].kind, "deviation");
    assert_eq!(rec.events[0].detail, "tick 100 joint 2: value 0.05 limit 0.02");
    assert_eq!(rec.depth_images.len() as u64, FRAMES);
    assert_eq!(rec.sun_phase(), Some((vec![0.0, 0.5, 1.0], vec![10.0, 20.0, 30.0])));
}

#[test]
fn depth_as_16uc1_millimetres() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("mm.mcap");
    let cfg = RecorderConfig {
        depth_output: DepthOutput::Millimetres16,
        compression: ChunkCompression::Zstd(1),
        ..Default::default()
    };
    write_run(&path, cfg);
    let pixels = [0usize, 3, 64];
    let v = python_read(&path, &pixels);
    let d = &v["depth"];
    assert_eq!(d["encoding"], "16UC1");
    for (n, &i) in pixels.iter().enumerate() {
        let want = (f64::from(depth_value(0, i)) * 1000.0).round() / 1000.0;
        let got = d["pixels_m"][n].as_f64().unwrap_or(f64::NAN);
        assert!((got - want).abs() < 1e-9, "pixel {i}: {got} vs {want}");
    }
    let rec = read_recording(&path).expect("read");
    assert_eq!(rec.depth_images[0].encoding, "16UC1");
}
