//! Issue 30 end to end: `hitl run --closed-loop` on the stub, whose target stands 5 mm (lab) from
//! where the controller's lab puts it (`--stub-config`). Open loop, a station-keeping plan ends
//! that far from its planned relative position; closed loop, within 0.5 mm; with a 2 mm corridor,
//! 2 mm better than open loop and no more. A fly-around closed loop stays inside its corridor at
//! every tick and tracks the planned relative path better than open loop; with perception stopped
//! mid-run the closed loop falls back to the plan (recorded) and the run completes; estimates that
//! lie (`--drill-perception-offset-m`) are gated, recorded, and fall back to the plan too.
//!
//! Every run is on the simulated clock (`--clock sim`, docs/sim-clock.md): the navigator takes its
//! turns in the lockstep, so the figures do not depend on the machine's load, and two runs of the
//! same inputs record the same `/closed_loop/*` messages.
//!
//! Errors are measured against the truth: forward kinematics of the recorded arm states against
//! the stub's target, compared with the plan's relative position (the open-loop run's setpoints,
//! which are the plan's, against the controller's target).

mod common;

use common::{hitl, text, SHARED_VM_LAB, SIM_CAPTURE_RUN, STUB_5MM_OFF};
use hitl_record::reader::{read_recording, Recording};
use hitl_record::Phase;
use hitl_trajectories::kinematics::camera_pose;
use hitl_trajectories::lab::LabConfig;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::Mutex;

/// Runs of the embedded stub, one at a time (each renders and estimates on the CI's 2 cores).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn plan(dir: &Path, preset: &str, range_m: &str, duration_s: &str) -> PathBuf {
    let out = dir.join(format!("{preset}-{range_m}.npz"));
    let p = hitl(&[
        "plan",
        "--preset",
        preset,
        "--range-m",
        range_m,
        "--duration-s",
        duration_s,
        "--capture-every",
        "5",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    assert_eq!(p.status.code(), Some(0), "{}", text(&p));
    out
}

/// A played run: its output, recording and where its playback lies in loop ticks.
struct Played {
    out: Output,
    mcap: PathBuf,
    rec: Recording,
    first: u64,
    ticks: u64,
}

fn play(traj: &Path, name: &str, extra: &[&str]) -> Played {
    let mcap = traj.with_file_name(format!("{name}.mcap"));
    let mut args = vec![
        "run",
        traj.to_str().expect("utf-8"),
        "--record",
        mcap.to_str().expect("utf-8"),
        "--perception",
        "icp",
        "--stub-config",
        STUB_5MM_OFF,
        "--clock",
        "sim",
    ];
    args.extend_from_slice(&SIM_CAPTURE_RUN);
    args.extend_from_slice(extra);
    let out = {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        hitl(&args)
    };
    assert_eq!(out.status.code(), Some(0), "{name}: {}", text(&out));
    let rec = read_recording(&mcap).expect("readable recording");
    let summary = text(&out);
    let count = |what: &str| -> u64 {
        let at = summary.find(&format!(" {what}")).expect(what);
        let head = &summary[..at];
        head.rsplit(|c: char| !c.is_ascii_digit()).next().and_then(|n| n.parse().ok()).expect(what)
    };
    Played { rec, first: count("approach,"), ticks: count("playback"), out, mcap }
}

struct Labs {
    mount: hitl_hal::Pose,
    believed: Vector3<f64>,
    truth: Vector3<f64>,
}

fn labs() -> Labs {
    let believed = LabConfig::load(Path::new(SHARED_VM_LAB)).expect("lab");
    let truth = LabConfig::load(Path::new(STUB_5MM_OFF)).expect("stub lab");
    Labs {
        mount: believed.camera_mount(),
        believed: believed.target_position_base().coords,
        truth: truth.target_position_base().coords,
    }
}

fn cam(q: &[f64; 7], l: &Labs) -> Vector3<f64> {
    camera_pose(q, &l.mount).translation.vector
}

/// Playback setpoints by tick offset from the playback's first tick.
fn playback_setpoints(p: &Played) -> Vec<[f64; 7]> {
    let mut out = vec![[f64::NAN; 7]; p.ticks as usize];
    for s in p.rec.setpoints.iter().filter(|s| s.phase == Phase::Playback) {
        if let Some(i) = s.tick.checked_sub(p.first).filter(|i| *i < p.ticks) {
            out[i as usize] = s.q;
        }
    }
    out
}

/// The measured joints at the playback's tick `i` (the last report at or before it).
fn measured_at(p: &Played, i: u64) -> [f64; 7] {
    let t = p.rec.setpoints.iter().find(|s| s.tick == p.first + i).expect("setpoint").t_ns;
    p.rec.states.iter().take_while(|s| s.t_ns <= t).last().expect("a report").q
}

/// How far the chaser is from its planned relative position at playback tick `i`, metres.
fn relative_error(p: &Played, plan: &[[f64; 7]], i: u64, l: &Labs) -> f64 {
    let achieved = cam(&measured_at(p, i), l) - l.truth;
    let planned = cam(&plan[i as usize], l) - l.believed;
    (achieved - planned).norm()
}

fn topic_count(rec: &Recording, topic: &str) -> usize {
    rec.closed_loop.iter().filter(|(t, _, _)| t == topic).count()
}

#[test]
fn station_keeping_ends_on_its_planned_relative_position_closed_loop() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), "station-keeping", "10", "30");
    let l = labs();
    let open = play(&traj, "open", &[]);
    let closed = play(&traj, "closed", &["--closed-loop"]);
    let narrow = play(&traj, "narrow", &["--closed-loop", "--corridor-m", "0.002"]);
    let plan = playback_setpoints(&open);
    let last = open.ticks - 1;
    let open_err = relative_error(&open, &plan, last, &l);
    let closed_err = relative_error(&closed, &plan, last, &l);
    let narrow_err = relative_error(&narrow, &plan, last, &l);
    eprintln!(
        "station keeping, end of playback: open {:.3} mm, closed {:.3} mm, 2 mm corridor {:.3} mm",
        open_err * 1e3,
        closed_err * 1e3,
        narrow_err * 1e3
    );
    assert!((open_err - 0.005).abs() < 0.0005, "open loop ends {:.3} mm off", open_err * 1e3);
    assert!(closed_err < 0.0005, "closed loop ends {:.3} mm off", closed_err * 1e3);
    // Every decision is recorded on its own topic; every estimate was used.
    let gates: Vec<_> =
        closed.rec.closed_loop.iter().filter(|(t, _, _)| t == "/closed_loop/gate").collect();
    assert!(gates.len() > 40, "{} gate decisions", gates.len());
    assert!(gates.iter().all(|(_, _, g)| g["used"] == true), "{gates:?}");
    assert!(topic_count(&closed.rec, "/closed_loop/filter") >= gates.len());
    assert!(topic_count(&closed.rec, "/closed_loop/correction") > 10);
    assert!(open.rec.closed_loop.is_empty(), "open loop records no closed-loop topic");
    let md = &closed.rec.metadata["closed_loop"];
    assert_eq!(md["fallback"], "");
    assert!(text(&closed.out).contains("closed loop: estimates used"), "{}", text(&closed.out));
    report_shows_open_and_closed(&closed, closed_err);

    // A 2 mm corridor: every recorded correction within it, the wanted ones clamped to it, and
    // the end 2 mm closer than open loop, no more.
    let corrections = sent_corrections(&narrow.rec);
    assert!(corrections.len() > 10, "{} corrections sent", corrections.len());
    let largest = corrections.iter().map(|(c, _)| c.norm()).fold(0.0, f64::max);
    assert!(largest <= 0.002 + 1e-9, "a correction of {:.4} mm", largest * 1e3);
    assert!(largest > 0.002 - 1e-6, "the corridor was reached ({:.4} mm)", largest * 1e3);
    assert!(corrections.iter().any(|(_, clamped)| *clamped), "some were clamped");
    assert!(
        (narrow_err - (open_err - 0.002)).abs() < 0.0005,
        "the 2 mm corridor ends {:.3} mm off (open loop {:.3} mm)",
        narrow_err * 1e3,
        open_err * 1e3
    );
    assert_eq!(narrow.rec.metadata["closed_loop"]["corridor_m"], "0.002");
}

/// `hitl report` of the closed-loop run plots the relative-position error open and closed, and
/// its `summary.json` carries the figures: vision's 5 mm open loop, and closed loop the end
/// within 0.5 mm and near the truth's `closed_err`.
fn report_shows_open_and_closed(closed: &Played, closed_err: f64) {
    let dir = closed.mcap.with_file_name("closed_report");
    let out = hitl(&[
        "report",
        closed.mcap.to_str().expect("utf-8"),
        "--out",
        dir.to_str().expect("utf-8"),
        "--contact-frames",
        "0",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).expect("summary JSON");
    let e = &summary["closed_loop_error"];
    let f = |v: &serde_json::Value| v.as_f64().expect("a number");
    let (open_mean, closed_mean) = (f(&e["open_mm"]["mean"]), f(&e["closed_mm"]["mean"]));
    let (open_last, closed_last) = (f(&e["last"]["open_mm"]), f(&e["last"]["closed_mm"]));
    eprintln!(
        "report: open loop mean {open_mean:.3} mm (last {open_last:.3}), closed loop mean \
         {closed_mean:.3} mm (last {closed_last:.3})"
    );
    assert!((open_mean - 5.0).abs() < 0.5 && (open_last - 5.0).abs() < 0.5, "{e}");
    assert!(closed_last < 0.5, "{e}");
    assert!(closed_mean < 0.5 * open_mean, "{e}");
    assert!((closed_last - closed_err * 1e3).abs() < 0.5, "vision and the truth agree: {e}");
    let captures = e["per_capture"].as_array().expect("per capture").len();
    assert_eq!(captures, topic_count(&closed.rec, "/closed_loop/filter"));
    let svg = std::fs::read_to_string(dir.join("closed_loop_error.svg")).expect("the plot");
    assert!(svg.contains("closed loop (with the correction in effect)"), "the plot's legend");
}

/// The corrections a run sent (`/closed_loop/correction`, neither refused nor a return to the
/// plan): the camera correction in lab metres, and whether the corridor clamped it.
fn sent_corrections(rec: &Recording) -> Vec<(Vector3<f64>, bool)> {
    rec.closed_loop
        .iter()
        .filter(|(t, _, _)| t == "/closed_loop/correction")
        .filter_map(|(_, _, c)| {
            let v = c["correction_lab_m"].as_array()?;
            let f = |i: usize| v[i].as_f64().expect("a number");
            Some((Vector3::new(f(0), f(1), f(2)), c["clamped"] == true))
        })
        .collect()
}

#[test]
fn two_simulated_closed_loop_runs_record_the_same_decisions() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), "station-keeping", "10", "8");
    let a = play(&traj, "a", &["--closed-loop"]);
    let b = play(&traj, "b", &["--closed-loop"]);
    for topic in ["/closed_loop/filter", "/closed_loop/gate", "/closed_loop/correction"] {
        let of = |p: &Played| -> Vec<(u64, String)> {
            p.rec
                .closed_loop
                .iter()
                .filter(|(t, _, _)| t == topic)
                .map(|(_, t_ns, m)| (*t_ns, m.to_string()))
                .collect()
        };
        let (ma, mb) = (of(&a), of(&b));
        assert!(!ma.is_empty(), "{topic} recorded");
        assert_eq!(ma, mb, "{topic} differs between two runs of the same inputs");
    }
    let setpoints = |p: &Played| -> Vec<(u64, [u64; 7])> {
        p.rec.setpoints.iter().map(|s| (s.tick, s.q.map(f64::to_bits))).collect()
    };
    assert_eq!(setpoints(&a), setpoints(&b), "the corrected setpoints differ");
}

#[test]
fn a_flyaround_closed_loop_tracks_better_inside_its_corridor_and_falls_back_without_perception() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), "flyaround", "10", "20");
    let l = labs();
    // Half speed (as tests/approach_retreat.rs: a stalled stub on a loaded machine trips the
    // deviation limit at full speed); the tracker re-registers every 4 frames (as
    // tests/run_perception.rs), so a lost track does not end the closed loop.
    let half = ["--speed-scale", "0.5", "--reregister-every", "4"];
    let with = |extra: &[&'static str]| [&half[..], extra].concat();
    let open = play(&traj, "open", &half);
    let closed = play(&traj, "closed", &with(&["--closed-loop"]));
    let narrow = play(&traj, "narrow", &with(&["--closed-loop", "--corridor-m", "0.002"]));
    let plan = playback_setpoints(&open);
    for p in [&closed, &narrow] {
        assert_eq!(p.rec.metadata["closed_loop"]["fallback"], "", "no fallback without a drill");
    }
    for (t, _, c) in closed
        .rec
        .closed_loop
        .iter()
        .filter(|(t, _, c)| t == "/closed_loop/correction" && c.get("refused").is_some())
    {
        eprintln!("{t}: {c}");
    }

    // Inside the corridor at every tick (the default 6 mm; 2 mm when asked).
    for (p, radius) in [(&closed, 0.006), (&narrow, 0.002)] {
        let sent = playback_setpoints(p);
        let worst = (0..p.ticks as usize)
            .filter(|i| !sent[*i][0].is_nan() && !plan[*i][0].is_nan())
            .map(|i| (cam(&sent[i], &l) - cam(&plan[i], &l)).norm())
            .fold(0.0, f64::max);
        assert!(worst <= radius + 1e-6, "a corrected setpoint {:.3} mm from the plan", worst * 1e3);
        assert!(worst > 0.5 * radius, "the closed loop corrected ({:.3} mm)", worst * 1e3);
    }
    // Tracking over the second half of the playback: closed loop better than open.
    let mean = |p: &Played| {
        let range = p.ticks / 2..p.ticks - 1;
        let n = range.clone().count() as f64;
        range.map(|i| relative_error(p, &plan, i, &l)).sum::<f64>() / n
    };
    let (e_open, e_closed, e_narrow) = (mean(&open), mean(&closed), mean(&narrow));
    eprintln!(
        "fly-around, mean relative error over the second half: open {:.3} mm, closed {:.3} mm, 2 mm corridor {:.3} mm",
        e_open * 1e3,
        e_closed * 1e3,
        e_narrow * 1e3
    );
    assert!(e_open > 0.004, "open loop {:.3} mm", e_open * 1e3);
    assert!(
        e_closed < 0.7 * e_open,
        "closed {:.3} mm vs open {:.3} mm",
        e_closed * 1e3,
        e_open * 1e3
    );
    // The 2 mm corridor takes about 2 mm off the 5 mm error, no more.
    let gained = e_open - e_narrow;
    assert!((0.0012..0.0028).contains(&gained), "the 2 mm corridor gained {:.3} mm", gained * 1e3);

    // Perception stopped 6 s into the playback: every capture after it is missing, the closed
    // loop falls back (recorded), and the run completes on the plan.
    let stop = play(&traj, "stop", &with(&["--closed-loop", "--drill-perception-stop-s", "6"]));
    let first_missing = falls_back_to_the_plan(&stop, &plan, &l, "missing");
    assert!(first_missing >= stop.first + 6 * 250, "missing from tick {first_missing}");

    // Estimates that lie 80 mm from 6 s on: each is gated (recorded with its Mahalanobis
    // distance), five in a row fall back to the plan (recorded), and the run completes. (A 20 mm
    // lie at a capture a second is taken after about four: the filter, told nothing, grows unsure
    // enough; docs/closed-loop.md.)
    let lie = play(
        &traj,
        "lie",
        &with(&[
            "--closed-loop",
            "--drill-perception-offset-m",
            "0.08",
            "--drill-perception-offset-s",
            "6",
        ]),
    );
    let first_gated = falls_back_to_the_plan(&lie, &plan, &l, "gated");
    let drill_tick = lie.first + 6 * 250;
    assert!(first_gated >= drill_tick, "gated from tick {first_gated}");
    let gates: Vec<&serde_json::Value> = lie
        .rec
        .closed_loop
        .iter()
        .filter(|(t, _, _)| t == "/closed_loop/gate")
        .map(|(_, _, g)| g)
        .collect();
    let tick = |g: &serde_json::Value| g["tick"].as_u64().expect("tick");
    let (before, after): (Vec<&serde_json::Value>, Vec<&serde_json::Value>) =
        gates.into_iter().partition(|g| tick(g) < drill_tick);
    assert!(before.len() > 5, "{} estimates before the drill", before.len());
    assert!(before.iter().all(|g| g["used"] == true), "{before:?}");
    // The five that fell back (later ones may pass again: a filter that has been told nothing
    // for long grows unsure enough to take them, and is no longer obeyed).
    for g in &after[..5] {
        assert_eq!((&g["used"], &g["reason"]), (&false.into(), &"gated".into()), "{g}");
        let d2 = g["mahalanobis2"].as_f64().expect("a distance");
        assert!(d2 > 16.266, "gated at a squared Mahalanobis distance of {d2}");
    }
    assert_eq!(lie.rec.metadata["closed_loop"]["drill_perception_offset_m"], "0.08");
}

/// A drilled run fell back to the plan for `reason` once (said, recorded as an event and in the
/// metadata), after at least five captures in a row recorded as unusable for it, and ended on the
/// plan's setpoints; the tick of the first capture recorded unusable.
fn falls_back_to_the_plan(p: &Played, plan: &[[f64; 7]], l: &Labs, reason: &str) -> u64 {
    assert!(text(&p.out).contains("fell back to the plan"), "{}", text(&p.out));
    let events: Vec<_> =
        p.rec.events.iter().filter(|e| e.detail.contains("fell back to the plan")).collect();
    assert_eq!(events.len(), 1, "{:?}", p.rec.events);
    assert!(events[0].detail.contains(reason), "{}", events[0].detail);
    let fallback = &p.rec.metadata["closed_loop"]["fallback"];
    assert!(fallback.contains(reason), "the fallback is in the metadata: {fallback:?}");
    let unusable: Vec<u64> = p
        .rec
        .closed_loop
        .iter()
        .filter(|(t, _, g)| t == "/closed_loop/gate" && g["reason"] == reason)
        .map(|(_, _, g)| g["tick"].as_u64().expect("tick"))
        .collect();
    assert!(unusable.len() >= 5, "{} captures recorded {reason}", unusable.len());
    // After the fallback the setpoints are the plan's again.
    let sent = playback_setpoints(p);
    for i in (p.ticks * 3 / 4) as usize..p.ticks as usize {
        let d = (cam(&sent[i], l) - cam(&plan[i], l)).norm();
        assert!(d < 1e-6, "tick {i}: {:.4} mm from the plan after the fallback", d * 1e3);
    }
    unusable.into_iter().min().expect("one")
}

#[test]
fn closed_loop_refuses_what_it_cannot_close_on_before_anything_moves() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = plan(dir.path(), "station-keeping", "10", "5");
    let traj = traj.to_str().expect("utf-8");
    let base = ["run", traj, "--plain", "--config", SHARED_VM_LAB, "--closed-loop"];
    let cases: [(&[&str], &str); 3] = [
        (&["--camera", "none"], "needs a camera and a pose estimator"),
        (&["--camera", "sim", "--perception", "icp", "--corridor-m", "0"], "--corridor-m"),
        (&["--camera", "sim", "--perception", "icp", "--corridor-m", "0.2"], "--corridor-m"),
    ];
    for (extra, says) in cases {
        let out = hitl(&[&base[..], extra].concat());
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {}", text(&out));
        assert!(text(&out).contains(says), "{extra:?}: {}", text(&out));
        assert!(!text(&out).contains("approach"), "nothing moved: {}", text(&out));
    }
    // --corridor-m means nothing open loop.
    let out = hitl(&["run", traj, "--corridor-m", "0.004"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
}
