//! Issue 28 end to end: `hitl run --clock sim` plays a fly-around on simulated time in lockstep
//! with the embedded stub. Two runs of the same inputs, ICP on, record byte-identical messages on
//! every topic whose payloads the lockstep fixes (arm state, setpoints, camera, ground truth,
//! estimates); every stamp is simulated time; a stub fault fires at its simulated time and trips
//! as on the host's clock; `--clock sim --arm HOST` is refused before anything connects.

mod common;

use common::{hitl, plan_flyaround, SIM_CAPTURE_RUN};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Output;

/// The topics whose payloads two runs of the same inputs repeat exactly.
const REPEATED: [&str; 5] =
    ["/arm/state", "/arm/setpoint", "/camera/", "/pose/gt", "/pose/estimate"];

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// Each repeated topic's payloads, in the order they were written.
fn payloads(mcap: &Path) -> BTreeMap<String, Vec<Vec<u8>>> {
    let bytes = std::fs::read(mcap).expect("recording");
    let mut topics: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("mcap") {
        let m = m.expect("message");
        let topic = m.channel.topic.clone();
        if REPEATED.iter().any(|t| topic.starts_with(t)) {
            topics.entry(topic).or_default().push(m.data.into_owned());
        }
    }
    topics
}

fn run_sim(traj: &Path, mcap: &Path, extra: &[&str]) -> Output {
    let (t, m) = (traj.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    let args = [&["run", t, "--record", m, "--clock", "sim"][..], &SIM_CAPTURE_RUN, extra].concat();
    hitl(&args)
}

#[test]
fn two_sim_clock_runs_with_icp_record_the_same_messages() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("fly.npz");
    plan_flyaround(&traj, "10", "20");
    let icp = ["--perception", "icp", "--no-retreat"];
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    let first = run_sim(&traj, &a, &icp);
    assert_eq!(first.status.code(), Some(0), "{}", text(&first));
    assert!(text(&first).contains("simulated clock:"), "{}", text(&first));
    let second = run_sim(&traj, &b, &icp);
    assert_eq!(second.status.code(), Some(0), "{}", text(&second));

    let (pa, pb) = (payloads(&a), payloads(&b));
    for topic in ["/arm/state", "/arm/setpoint", "/pose/gt", "/pose/estimate"] {
        assert!(pa.get(topic).is_some_and(|v| !v.is_empty()), "{topic} recorded: {:?}", pa.keys());
    }
    assert!(pa.keys().any(|t| t.starts_with("/camera/")), "{:?}", pa.keys());
    assert_eq!(pa.keys().collect::<Vec<_>>(), pb.keys().collect::<Vec<_>>());
    for (topic, msgs) in &pa {
        let other = &pb[topic];
        assert_eq!(msgs.len(), other.len(), "{topic}: message counts differ");
        let first_diff = msgs.iter().zip(other).position(|(x, y)| x != y);
        assert_eq!(first_diff, None, "{topic}: payloads differ from message {first_diff:?}");
    }

    // Every stamp is simulated time: the setpoints are whole ticks of 4 ms from the start.
    let rec = hitl_record::reader::read_recording(&a).expect("recording");
    assert!(rec.setpoints.len() > 1000, "{} setpoints", rec.setpoints.len());
    for s in rec.setpoints.iter().take(500) {
        assert_eq!(s.t_ns, (s.tick + 1) * 4_000_000, "tick {} at {} ns", s.tick, s.t_ns);
    }
}

#[test]
fn a_stub_fault_fires_at_its_simulated_time() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("fly.npz");
    plan_flyaround(&traj, "10", "20");
    let mcap = dir.path().join("fault.mcap");
    let run = run_sim(&traj, &mcap, &["--stub-fault", "estop@3"]);
    let out = text(&run);
    assert_eq!(run.status.code(), Some(4), "{out}");
    assert!(out.contains("stopped by estop"), "{out}");
    // The e-stop input is read at the first tick at or after 3 s of simulated time.
    let rec = hitl_record::reader::read_recording(&mcap).expect("recording");
    let trip = rec.events.iter().find(|e| e.kind == "e-stop").expect("e-stop");
    assert!((3_000_000_000..3_010_000_000).contains(&trip.t_ns), "tripped at {} ns", trip.t_ns);
}

#[test]
fn the_simulated_clock_refuses_a_real_arm_before_connecting() {
    // 192.0.2.1 (TEST-NET-1) answers nobody: a connection attempt would hang, not exit 2.
    let t = std::time::Instant::now();
    let out = hitl(&["run", "missing.npz", "--arm", "192.0.2.1", "--clock", "sim"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("--clock sim runs on the embedded stub only"), "{}", text(&out));
    assert!(t.elapsed() < std::time::Duration::from_secs(5));
}
