//! Perception end to end on the stub: a fly-around played with the simulated camera and the ICP
//! tracker under a re-registration policy records an estimate per capture that meets the paper's
//! accuracy goal; `hitl eval --backend icp` re-runs the recorded frames under the policy the run
//! recorded and, the tracker being deterministic, gives the same figures; bad policies are
//! refused before anything moves.

use hitl_record::reader::read_recording;
use hitl_trajectories::npz;

mod common;
use common::{hitl, num, plan_flyaround, SIM_CAPTURE_RUN, SIM_CLOCK};

fn json(out: &std::process::Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!("not one JSON object ({e}): {text}{}", String::from_utf8_lossy(&out.stderr))
    })
}

#[test]
fn a_live_icp_run_meets_the_goal_and_an_offline_rerun_repeats_it_under_the_recorded_policy() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("fly.npz");
    let mcap = dir.path().join("run.mcap");
    let (t, m) = (traj.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    let range_m = 10.0;
    plan_flyaround(&traj, "10", "20");
    let captures = npz::load(&traj).expect("plan").trajectory.capture_count() as u64;
    assert!(captures >= 8, "{captures} captures");

    let policy = ["--perception", "icp", "--reregister-every", "4"];
    let args = [&["run", t, "--record", m][..], &policy, &SIM_CAPTURE_RUN, &SIM_CLOCK].concat();
    let run = hitl(&args);
    let out =
        format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert_eq!(run.status.code(), Some(0), "{out}");
    let rec = read_recording(&mcap).expect("recording");
    assert_eq!(
        rec.metadata["run"]["perception_reregister"],
        r#"{"every_n_frames":4,"max_residual_m":null}"#
    );

    // Live: the estimates the worker wrote, scored against ground truth.
    let live = hitl(&["eval", m, "--json"]);
    assert_eq!(live.status.code(), Some(0), "{}", String::from_utf8_lossy(&live.stderr));
    let live = json(&live);
    assert_eq!(live["frames"].as_u64(), Some(captures), "{live}");
    assert!(live["failures"].as_u64().is_some_and(|f| f <= 2), "{live}");
    assert!(num(&live, "mean_et_m") <= 0.01 * range_m, "{live}");
    assert!(num(&live, "mean_er_deg") <= 1.5, "{live}");

    // Offline, no policy flags: the recorded one (resets before frames 4 and 8, at least).
    let offline = hitl(&["eval", m, "--backend", "icp", "--json"]);
    assert_eq!(offline.status.code(), Some(0), "{}", String::from_utf8_lossy(&offline.stderr));
    let offline = json(&offline);
    assert_eq!(offline["reregister"]["every_n_frames"].as_u64(), Some(4), "{offline}");
    assert!(offline["backend_resets"].as_u64().is_some_and(|r| r >= 2), "{offline}");
    assert_eq!(offline["replayed_frames"].as_u64(), Some(captures), "{offline}");
    // The same poses, up to the rounding of the recording's quaternion form of the live ones.
    assert_eq!(offline["failures"], live["failures"], "offline {offline} live {live}");
    for key in ["mean_et_m", "mean_er_deg", "median_er_deg"] {
        let (a, b) = (num(&offline, key), num(&live, key));
        assert!((a - b).abs() <= 1e-9 * b.abs().max(1e-3), "{key}: offline {a} live {b}");
    }

    // A policy given on the command line replaces the recorded one.
    let never = hitl(&["eval", m, "--backend", "icp", "--reregister-every", "1000", "--json"]);
    assert_eq!(never.status.code(), Some(0), "{}", String::from_utf8_lossy(&never.stderr));
    let never = json(&never);
    assert_eq!(never["reregister"]["every_n_frames"].as_u64(), Some(1000), "{never}");
    let lost = never["failures"].as_u64().unwrap_or(u64::MAX);
    assert_eq!(never["backend_resets"].as_u64(), Some(lost), "only lost frames reset: {never}");

    // The text output says which backend ran under which policy.
    let text = hitl(&["eval", m, "--backend", "icp"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains(
            "backend icp, re-registered on the first frame and after a lost one, every 4 frames: "
        ),
        "{text}"
    );

    // Bad policies: exit 2 with the value named; a policy with no re-run to apply to, too.
    let bad = hitl(&["eval", m, "--backend", "icp", "--reregister-every", "0"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("at least 1"), "{bad:?}");
    let idle = hitl(&["eval", m, "--reregister-every", "3"]);
    assert_eq!(idle.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&idle.stderr).contains("--backend"), "{idle:?}");
}

#[test]
fn a_bad_reregistration_policy_is_refused_before_anything_moves() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mcap = dir.path().join("never.mcap");
    let preset = concat!(env!("CARGO_MANIFEST_DIR"), "/trajectories/presets");
    let traj = std::fs::read_dir(preset)
        .expect("presets")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "npz"))
        .expect("a preset NPZ");
    let run = hitl(&[
        "run",
        traj.to_str().expect("utf-8"),
        "--record",
        mcap.to_str().expect("utf-8"),
        "--perception",
        "icp",
        "--reregister-residual-m",
        "-0.5",
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(err.contains("-0.5") && err.contains("residual"), "{err}");
    assert!(!mcap.exists(), "nothing was recorded, so nothing ran");

    // A policy with no estimator to drive.
    let idle = hitl(&["run", traj.to_str().expect("utf-8"), "--reregister-every", "5"]);
    let err = String::from_utf8_lossy(&idle.stderr);
    assert_eq!(idle.status.code(), Some(2), "{err}");
    assert!(err.contains("--perception"), "{err}");
}
