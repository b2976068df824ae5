//! Issue 30's closed loop on the host's clock (`--clock realtime`, the default): the navigator's
//! free-running loop (`run_freely` in src/closed_loop/navigator.rs), which tests/closed_loop.rs
//! no longer reaches since its runs moved to the simulated clock. One short station-keeping run
//! through `hitl run --closed-loop` on the stub, whose target stands 5 mm (lab) from where the
//! controller's lab puts it (`--stub-config`), as in tests/closed_loop.rs.
//!
//! On the host's clock the estimates arrive when the machine delivers them, so this test asserts
//! only what holds on a loaded machine (the shared-VM lab's limits, a small image, a plan of
//! 12 s): the run completes and ends at rest with exit 0; every capture gets a recorded decision
//! and most estimates are used; every correction stays inside the corridor; and over the second
//! half of the playback the chaser holds within 2.5 mm (half the open loop's 5 mm, which
//! tests/closed_loop.rs measures) of its planned relative position to the target it sees.
//! Measured on this 2-core machine, shared with other builds, four runs: 25 of 25 estimates
//! used, at most 1.24-1.63 mm over the second half, 1.07-1.45 mm at the end; the same 12 s plan on
//! the simulated clock holds 1.1-1.4 mm (not yet settled: its 30 s plan ends 0.15 mm off), so the
//! bound is about the plan's length, not the clock.

mod common;

use common::{hitl, text, SHARED_VM_LAB, SIM_CAPTURE_RUN, STUB_5MM_OFF};
use hitl_record::reader::{read_recording, Recording};
use hitl_trajectories::kinematics::{camera_pose, Joints};
use hitl_trajectories::lab::LabConfig;
use nalgebra::Vector3;
use std::path::Path;

/// The closed loop's default corridor (`--corridor-m`), metres.
const DEFAULT_CORRIDOR_M: f64 = 0.006;

/// The number just before ` {what}` in the run's summary (e.g. `1687 approach,`).
fn count(summary: &str, what: &str) -> u64 {
    let at = summary.find(&format!(" {what}")).expect(what);
    let head = &summary[..at];
    head.rsplit(|c: char| !c.is_ascii_digit()).next().and_then(|n| n.parse().ok()).expect(what)
}

/// The number just after `what` in the run's summary (e.g. `\ncaptures ` then `25,`).
fn after(summary: &str, what: &str) -> u64 {
    let at = summary.rfind(what).expect(what) + what.len();
    let digits: String = summary[at..].chars().take_while(char::is_ascii_digit).collect();
    digits.parse().expect(what)
}

/// The measured joints at loop tick `tick` (the last report at or before its setpoint).
fn measured_at(rec: &Recording, tick: u64) -> Joints {
    let t = rec.setpoints.iter().find(|s| s.tick == tick).expect("setpoint").t_ns;
    rec.states.iter().take_while(|s| s.t_ns <= t).last().expect("a report").q
}

fn topic<'a>(rec: &'a Recording, name: &str) -> Vec<&'a serde_json::Value> {
    rec.closed_loop.iter().filter(|(t, _, _)| t == name).map(|(_, _, m)| m).collect()
}

#[test]
fn station_keeping_closed_loop_on_the_hosts_clock_holds_its_relative_position() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("station-keeping.npz");
    let mcap = dir.path().join("realtime.mcap");
    let (traj_s, mcap_s) = (traj.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    let p = hitl(&[
        "plan",
        "--preset",
        "station-keeping",
        "--range-m",
        "10",
        "--duration-s",
        "12",
        "--capture-every",
        "5",
        "--out",
        traj_s,
    ]);
    assert_eq!(p.status.code(), Some(0), "{}", text(&p));
    // No --clock: the host's clock is the default.
    let mut args = vec![
        "run",
        traj_s,
        "--record",
        mcap_s,
        "--perception",
        "icp",
        "--stub-config",
        STUB_5MM_OFF,
        "--closed-loop",
    ];
    args.extend_from_slice(&SIM_CAPTURE_RUN);
    let out = hitl(&args);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(!all.contains("lockstep"), "a host-clock run: {all}");
    assert!(all.contains("then back at the rest pose"), "{all}");
    assert!(all.contains("closed loop: estimates used"), "{all}");
    let rec = read_recording(&mcap).expect("readable recording");

    // Every capture decided and recorded; most estimates used; the filter's state recorded for
    // each one used; no fallback.
    let captures = after(&all, "\ncaptures ");
    let gates = topic(&rec, "/closed_loop/gate");
    let used = gates.iter().filter(|g| g["used"] == true).count();
    eprintln!("host clock: {captures} captures, {} gate decisions, {used} used", gates.len());
    assert!(captures >= 20, "{captures} captures for a 12 s plan at 2 Hz");
    assert_eq!(gates.len() as u64, captures, "one decision per capture");
    assert!(used * 4 >= gates.len() * 3, "{used} of {} estimates used", gates.len());
    assert!(topic(&rec, "/closed_loop/filter").len() >= used);
    assert_eq!(rec.metadata["closed_loop"]["fallback"], "", "no fallback");

    // Corrections were sent, each inside the default corridor.
    let corrections: Vec<f64> = topic(&rec, "/closed_loop/correction")
        .iter()
        .filter_map(|c| {
            let v = c["correction_lab_m"].as_array()?;
            let f = |i: usize| v[i].as_f64().expect("a number");
            Some(Vector3::new(f(0), f(1), f(2)).norm())
        })
        .collect();
    assert!(corrections.len() >= 5, "{} corrections", corrections.len());
    let largest = corrections.iter().fold(0.0f64, |m, c| m.max(*c));
    assert!(largest <= DEFAULT_CORRIDOR_M + 1e-9, "a correction of {:.3} mm", largest * 1e3);
    assert!(largest > 0.003, "the closed loop corrected ({:.3} mm)", largest * 1e3);

    // The chaser's relative position at the end of the playback, against the stub's true target,
    // versus the plan's (its last waypoint against the target the controller believes).
    let believed = LabConfig::load(Path::new(SHARED_VM_LAB)).expect("lab");
    let truth = LabConfig::load(Path::new(STUB_5MM_OFF)).expect("stub lab");
    let mount = believed.camera_mount();
    let cam = |q: &Joints| camera_pose(q, &mount).translation.vector;
    let plan = hitl_trajectories::npz::load(&traj).expect("plan").trajectory;
    let planned =
        cam(plan.qpos.last().expect("waypoints")) - believed.target_position_base().coords;
    let error_at = |tick: u64| {
        let achieved = cam(&measured_at(&rec, tick)) - truth.target_position_base().coords;
        (achieved - planned).norm()
    };
    let (first, ticks) = (count(&all, "approach,"), count(&all, "playback"));
    let end = error_at(first + ticks - 1);
    let hold: Vec<f64> = (ticks / 2..ticks).step_by(25).map(|i| error_at(first + i)).collect();
    let worst = hold.iter().fold(0.0f64, |m, e| m.max(*e));
    eprintln!(
        "host clock: station keeping ends {:.3} mm off, at most {:.3} mm over the second half \
         (open loop: 5 mm)",
        end * 1e3,
        worst * 1e3
    );
    assert!(worst < 0.0025, "closed loop holds {:.3} mm off", worst * 1e3);
    assert!(end < 0.0025, "closed loop ends {:.3} mm off", end * 1e3);

    // At rest where the retreat goes.
    let last = rec.states.last().expect("a report");
    let rest = believed.arm.rest_q;
    let off = (0..7).map(|j| (last.q[j] - rest[j]).abs()).fold(0.0f64, f64::max);
    assert!(off < 0.01, "the arm ends {off:.4} rad from the rest pose");
}
