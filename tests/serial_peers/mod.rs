//! Peers and a trajectory shared by the end-to-end tests of the serial devices
//! (tests/run_devices.rs, tests/trigger_box_sim.rs): the Enttec DMX widget played on a pty, and
//! a 3 s sweep with four captures and a stepped light schedule.
#![allow(dead_code)] // each test binary uses its own subset

use crate::light_pty::PtyPeer;
use hitl_trajectories::{npz, Trajectory};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The stub's power-up pose (no approach).
pub const HOME: [f64; 7] = [0.0, -0.5, 0.0, 0.9, 0.0, 1.4, 0.0];

/// The light schedule: 0.2 for the first second, 0.6 for the second, 1.0 after.
pub fn level_at(t: f64) -> f32 {
    if t < 1.0 {
        0.2
    } else if t < 2.0 {
        0.6
    } else {
        1.0
    }
}

/// A 3 s sweep of joint 1 with captures at 0, 1, 2 and 3 s and the stepped light schedule.
pub fn trajectory(dir: &Path) -> PathBuf {
    let n = 31;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.1).collect();
    let qpos = t
        .iter()
        .map(|&t| {
            let mut q = HOME;
            q[0] = -0.3 * (std::f64::consts::PI * t / 3.0).sin().powi(2);
            q
        })
        .collect();
    let traj = Trajectory {
        qpos,
        capture: Some((0..n).map(|i| i % 10 == 0).collect()),
        light: Some(t.iter().map(|&t| level_at(t)).collect()),
        t,
        ..Default::default()
    };
    let path = dir.join("lit.npz");
    npz::save(&path, &traj, false).expect("write the trajectory");
    path
}

/// Channel 1 of every DMX frame received, with its arrival time.
pub fn decode_dmx(pending: &mut Vec<u8>, at: Instant, out: &mut Vec<(Instant, u8)>) {
    loop {
        // Resynchronise on the start byte; anything before it is not a message.
        match pending.iter().position(|&b| b == 0x7E) {
            Some(0) => {}
            Some(i) => {
                pending.drain(..i);
            }
            None => {
                pending.clear();
                return;
            }
        }
        if pending.len() < 4 {
            return;
        }
        assert_eq!(pending[1], 6, "label 6 (Output Only Send DMX Packet Request)");
        let len = usize::from(pending[2]) | usize::from(pending[3]) << 8;
        assert!((25..=513).contains(&len), "data length {len}");
        if pending.len() < 4 + len + 1 {
            return;
        }
        assert_eq!(pending[4], 0, "DMX start code 0");
        assert_eq!(pending[4 + len], 0xE7, "end byte");
        out.push((at, pending[5]));
        pending.drain(..4 + len + 1);
    }
}

/// Plays the widget: decodes frames until the run ends, or until channel 1 has shown
/// `close_at` (then it closes its end: the adapter is unplugged).
pub fn dmx_peer(peer: PtyPeer, close_at: Option<u8>, done: Arc<AtomicBool>) -> Vec<(Instant, u8)> {
    let mut peer = peer;
    let mut frames = Vec::new();
    let mut pending = Vec::new();
    while !done.load(Ordering::Acquire) {
        let bytes = peer.read_some(1, Duration::from_millis(10));
        pending.extend_from_slice(&bytes);
        decode_dmx(&mut pending, Instant::now(), &mut frames);
        if close_at.is_some_and(|v| frames.iter().any(|f| f.1 == v)) {
            drop(peer);
            return frames;
        }
    }
    frames
}

/// Channel-1 values in the order they changed.
pub fn changes(frames: &[(Instant, u8)]) -> Vec<u8> {
    let mut out: Vec<u8> = Vec::new();
    for &(_, v) in frames {
        if out.last() != Some(&v) {
            out.push(v);
        }
    }
    out
}
