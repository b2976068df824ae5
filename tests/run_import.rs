//! `hitl run` end to end on a trajectory made elsewhere, as it is: a numpy file sampled at 100 Hz
//! from a slow sine with no `t` (`--waypoint-rate 100`), moving at its first and last waypoints.
//! The run plays a lead-in from rest, the file, and a lead-out to rest, each recorded as its own
//! phase; the playback phase follows the file (interpolated at the same times) to 2e-3 rad over
//! its whole span, its first and last setpoints being the file's first and last waypoints.

use hitl_record::reader::read_recording;
use hitl_record::Phase;
use std::path::Path;
use std::process::Command;

mod common;
use common::{hitl, SHARED_VM_LAB};

/// The stub's power-up pose.
const HOME: [f64; 7] = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];
/// Waypoints per second, and seconds of motion.
const HZ: f64 = 100.0;
const SPAN_S: f64 = 3.0;

/// Joint 1 sweeps 0.1 rad at 0.2 Hz around `HOME`, from mid-motion to mid-motion; `qpos` only.
fn write_sine(path: &Path) {
    let script = format!(
        "import numpy as np\n\
         t = np.arange({n}) / {HZ}\n\
         q = np.tile({HOME:?}, ({n}, 1)).astype(float)\n\
         q[:, 0] += 0.1 * np.sin(2 * np.pi * 0.2 * t + 0.3)\n\
         np.savez(r'{}', qpos=q)\n",
        path.display(),
        n = (SPAN_S * HZ) as usize + 1,
    );
    let out = Command::new(env!("HITL_VENV_PYTHON"))
        .arg("-c")
        .arg(&script)
        .output()
        .expect("the venv's python (run make setup)");
    assert!(out.status.success(), "numpy: {}", String::from_utf8_lossy(&out.stderr));
}

/// The file's joint positions linearly interpolated at `t` seconds.
fn file_at(qpos: &[[f64; 7]], t: f64) -> [f64; 7] {
    let x = (t * HZ).clamp(0.0, (qpos.len() - 1) as f64);
    let i = (x.floor() as usize).min(qpos.len() - 2);
    let f = x - i as f64;
    std::array::from_fn(|j| qpos[i][j] + f * (qpos[i + 1][j] - qpos[i][j]))
}

#[test]
fn a_file_moving_at_both_ends_plays_as_written_between_a_lead_in_and_a_lead_out() {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = dir.path().join("orbit_piece.npz");
    write_sine(&traj);
    let mcap = dir.path().join("run.mcap");
    let (traj_s, mcap_s) = (traj.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    let base = ["run", traj_s, "--record", mcap_s, "--camera", "none", "--light", "none"];

    // Without its rate the file is refused before anything starts, naming `t` and the flag.
    let out = hitl(&[&base[..], &["--plain", "--config", SHARED_VM_LAB]].concat());
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("'t' is missing") && text.contains("--waypoint-rate HZ"), "{text}");

    let out = hitl(
        &[&base[..], &["--waypoint-rate", "100", "--plain", "--config", SHARED_VM_LAB]].concat(),
    );
    let text =
        format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert_eq!(out.status.code(), Some(0), "{text}");
    assert!(text.contains("settled on the last waypoint"), "{text}");

    let rec = read_recording(&mcap).expect("readable recording");
    let phases: Vec<Phase> = rec.setpoints.iter().map(|s| s.phase).collect();
    let count = |p: Phase| phases.iter().filter(|x| **x == p).count();
    assert!(count(Phase::LeadIn) > 0 && count(Phase::LeadOut) > 0, "phases {phases:?}");
    // In order: approach, lead-in, playback, lead-out, retreat (each one contiguous run).
    let mut order: Vec<Phase> = phases.clone();
    order.dedup();
    order.retain(|p| *p != Phase::Approach && *p != Phase::Retreat);
    assert_eq!(order, vec![Phase::LeadIn, Phase::Playback, Phase::LeadOut]);

    // Playback: 3 s at 250 Hz, 751 setpoints, following the file to 2e-3 rad.
    let qpos: Vec<[f64; 7]> = {
        let loaded = hitl_trajectories::npz::load_with(
            &traj,
            &hitl_trajectories::npz::LoadOptions { waypoint_rate_hz: Some(HZ) },
        )
        .expect("load");
        loaded.trajectory.qpos
    };
    let playback: Vec<_> = rec.setpoints.iter().filter(|s| s.phase == Phase::Playback).collect();
    assert_eq!(playback.len(), (SPAN_S * 250.0) as usize + 1);
    let first_tick = playback[0].tick;
    let mut worst = 0.0f64;
    for sp in &playback {
        let t = (sp.tick - first_tick) as f64 / 250.0;
        let want = file_at(&qpos, t);
        for (got, want) in sp.q.iter().zip(want) {
            worst = worst.max((got - want).abs());
        }
    }
    eprintln!("playback vs file (interpolated): worst {worst:.3e} rad over {SPAN_S} s");
    assert!(worst < 2e-3, "playback leaves the file by {worst} rad");
    assert_eq!(playback[0].q, qpos[0]);
    assert_eq!(playback[playback.len() - 1].q, qpos[qpos.len() - 1]);
    // The file's own velocity at its first waypoint (0.1 * 2 pi 0.2 * cos 0.3), not zero.
    let v0 = 0.1 * 2.0 * std::f64::consts::PI * 0.2 * 0.3f64.cos();
    assert!((playback[0].qd[0] - v0).abs() < 1e-4, "{} vs {v0}", playback[0].qd[0]);
    // The lead-out ends at rest, where the arm settled (the retreat to the rest pose follows).
    let last = rec.setpoints.iter().rfind(|s| s.phase == Phase::LeadOut).expect("lead-out");
    assert!(last.qd.iter().all(|v| *v == 0.0), "{:?}", last.qd);
    assert!(rec.events.is_empty(), "no safety events: {:?}", rec.events);
}
