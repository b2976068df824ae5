//! `hitl report` on a synthetic recording: the files exist and the summary's values are right.

mod common;

use common::*;
use hitl_hal::Pose;
use hitl_record::report::write_report;
use hitl_record::*;

#[test]
fn report_of_a_synthetic_run() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let (handle, tel) = Recorder::spawn(&path, &meta()).expect("spawn");
    let t0 = 1_000_000_000u64;
    // 2 s at 250 Hz; the arm lags by 0.01 rad on joint 3; every 10th tick wakes 100 us late.
    for k in 0..500u64 {
        let t = t0 + k * 4_000_000;
        let mut q = [0.1; 7];
        q[2] = 0.5;
        tel.push_setpoint(&SetpointMsg {
            tick: k,
            t_ns: t,
            phase: Phase::Playback,
            q,
            qd: [0.0; 7],
        });
        let mut m = q;
        m[2] -= 0.01;
        tel.push_state(&ArmStateMsg {
            t_ns: t + 500_000,
            q: m,
            state: 1,
            mode: 1,
            error_code: 0,
            warn_code: 0,
        });
        tel.push_timing(&TimingMsg {
            tick: k,
            t_ns: t,
            wake_late_ns: if k.is_multiple_of(10) { 100_000 } else { 10_000 },
            tick_ns: 20_000,
            overrun: false,
        });
        if k.is_multiple_of(25) {
            let fk = k / 25;
            // A camera delivers frames at its rate; this loop has no clock, so it waits for the
            // writer instead of overrunning the 16-frame queue (drops are tested elsewhere).
            let give_up = std::time::Instant::now() + std::time::Duration::from_secs(10);
            while !tel.frame_queue_has_room() && std::time::Instant::now() < give_up {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            assert!(tel.push_frame(frame(fk, t, true)), "frame {fk} not queued");
            let mut est = frame(fk, t, true).gt_pose.unwrap_or_else(Pose::identity);
            est.translation.vector[0] += 0.003; // 3 mm off
            tel.push_pose_estimate(&PoseStamped { capture_ns: t, pose: est });
            tel.push_light(&LightMsg { t_ns: t, level: 0.8 });
        }
        if k == 400 {
            tel.push_event(SafetyEventMsg::text(t, EventKind::OperatorStop, "Ctrl-C"));
        }
        if k.is_multiple_of(100) {
            std::thread::sleep(std::time::Duration::from_millis(3));
        }
    }
    handle.finish().expect("finish");

    let out = dir.path().join("report");
    let r = write_report(&path, Some(&out)).expect("report");
    for f in [
        "summary.json",
        "index.html",
        "joints.svg",
        "tracking_error.svg",
        "lateness.svg",
        "camera_path.svg",
        "sun_phase.svg",
        "pose_error.svg",
    ] {
        let p = out.join(f);
        let len = std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0);
        assert!(len > 200, "{f}: {len} bytes");
    }
    let s = &r.summary;
    assert!(s.complete);
    assert!((s.duration_s - (499.0 * 0.004 + 0.0005)).abs() < 1e-9, "{}", s.duration_s);
    let tr = s.tracking.as_ref().expect("tracking");
    assert_eq!(tr.samples, 500);
    assert!((tr.rms_rad[2] - 0.01).abs() < 1e-9);
    assert!(tr.rms_rad[0].abs() < 1e-12);
    assert!((tr.max_abs_deg - 0.01f64.to_degrees()).abs() < 1e-9);
    let late = s.timing.wake_late_us.as_ref().expect("lateness");
    assert_eq!(late.count, 500);
    assert!((late.p50 - 10.0).abs() < 1e-9);
    assert!((late.max - 100.0).abs() < 1e-9);
    assert!((late.mean - 19.0).abs() < 1e-9);
    // Frame k was exposed 2 ms + k us after its trigger (tests/common).
    let sync = s.capture_sync_ms.as_ref().expect("capture sync");
    assert_eq!(sync.count, 20);
    assert!((sync.mean - 2.0095).abs() < 1e-9 && (sync.max - 2.019).abs() < 1e-9, "{sync:?}");
    let pe = s.pose_error.as_ref().expect("pose error");
    assert_eq!(pe.pairs, 20);
    let tmm = pe.translation_mm.as_ref().expect("translation");
    assert!((tmm.mean - 3.0).abs() < 1e-6 && (tmm.max - 3.0).abs() < 1e-6);
    assert_eq!(s.events.len(), 1);
    assert_eq!(s.events[0].kind, "operator-stop");
    assert!((s.events[0].t_s - 1.6).abs() < 1e-9);
    assert_eq!(s.topic_counts["/camera/depth"], 20);
    assert_eq!(s.dropped.values().sum::<u64>(), 0);
    assert_eq!(s.trajectory_sha256.as_deref(), Some("ab".repeat(32).as_str()));

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("read"))
            .expect("json");
    assert_eq!(json["tracking"]["samples"], 500);
    let html = std::fs::read_to_string(out.join("index.html")).expect("html");
    assert!(html.contains("camera_path.svg") && html.contains("operator-stop"));
    let svg = std::fs::read_to_string(out.join("camera_path.svg")).expect("svg");
    assert!(svg.contains("x-z"));
}

#[test]
fn lead_in_and_lead_out_are_phases_of_their_own_in_the_recording_and_the_summary() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("run.mcap");
    let (handle, tel) = Recorder::spawn(&path, &meta()).expect("spawn");
    let phases =
        [(Phase::Approach, 5), (Phase::LeadIn, 3), (Phase::Playback, 10), (Phase::LeadOut, 4)];
    let mut k = 0u64;
    for (phase, n) in phases {
        for _ in 0..n {
            let t_ns = 1_000_000_000 + k * 4_000_000;
            tel.push_setpoint(&SetpointMsg { tick: k, t_ns, phase, q: [0.1; 7], qd: [0.0; 7] });
            k += 1;
        }
    }
    handle.finish().expect("finish");
    let rec = reader::read_recording(&path).expect("read");
    let read: Vec<Phase> = rec.setpoints.iter().map(|s| s.phase).collect();
    assert_eq!(read[5..8], [Phase::LeadIn; 3]);
    assert_eq!(read[18..], [Phase::LeadOut; 4]);
    let s = report::summarize(&rec);
    let by = |name: &str| s.setpoints_by_phase.get(name).copied();
    assert_eq!((by("approach"), by("lead_in")), (Some(5), Some(3)));
    assert_eq!((by("playback"), by("lead_out")), (Some(10), Some(4)));
    let out = dir.path().join("report");
    write_report(&path, Some(&out)).expect("report");
    let summary = std::fs::read_to_string(out.join("summary.json")).expect("summary");
    assert!(summary.contains("\"lead_in\":3") || summary.contains("\"lead_in\": 3"), "{summary}");
}
