//! `hitl run` end to end with the serial devices: a pseudo-terminal peer plays the Enttec DMX
//! widget or the trigger box (protocol 2, docs/trigger-box-protocol.md) while the binary drives
//! the embedded stub. The levels the peer receives follow the trajectory's light schedule, the
//! trigger box fires at the capture ticks, and every device fault (peer gone, door, e-stop,
//! input silence, `E` line) ends the run with its reaction, exit code and `/safety/event`, the
//! recording readable. Runs are serialised: each one drives a real-time loop and a physics thread.

mod common;
#[path = "../drivers/tests/light_pty/mod.rs"]
mod light_pty;
mod serial_peers;

use common::SHARED_VM_LAB;
use hitl_record::reader::{read_recording, Recording};
use hitl_record::Phase;
use hitl_trajectories::npz;
use hitl_trajectories::timing::SetpointTable;
use light_pty::PtyPeer;
use serial_peers::{changes, dmx_peer, trajectory};
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

struct Run {
    out: Output,
    rec: Recording,
    traj: PathBuf,
    _dir: tempfile::TempDir,
}

impl Run {
    fn code(&self) -> i32 {
        self.out.status.code().unwrap_or(-1)
    }
    fn text(&self) -> String {
        format!(
            "{}{}",
            String::from_utf8_lossy(&self.out.stdout),
            String::from_utf8_lossy(&self.out.stderr)
        )
    }
    fn has_event(&self, kind: &str) -> bool {
        self.rec.events.iter().any(|e| e.kind == kind)
    }
    fn stop_setpoints(&self) -> usize {
        self.rec.setpoints.iter().filter(|s| s.phase == Phase::Stop).count()
    }
    /// Tick numbers of the playback captures, as the loop counts them.
    fn capture_ticks(&self) -> Vec<u64> {
        let traj = npz::load(&self.traj).expect("load").trajectory;
        let table = SetpointTable::build(&traj, 250.0, 1.0).expect("table");
        let approach =
            self.rec.setpoints.iter().filter(|s| s.phase == Phase::Approach).count() as u64;
        table.captures.iter().map(|c| approach + c.tick as u64).collect()
    }
}

/// Plays the test trajectory with `--light LIGHT` while `peer` runs on its own thread until the
/// run ends (it is told through the flag); returns the run and what the peer returned.
fn run_with_peer<T: Send + 'static>(
    light: &str,
    peer: impl FnOnce(Arc<AtomicBool>) -> T + Send + 'static,
) -> (Run, T) {
    run_with_devices(&["--light", light], peer)
}

/// Plays the test trajectory with these device flags (no camera) while `peer` runs.
fn run_with_devices<T: Send + 'static>(
    devices: &[&str],
    peer: impl FnOnce(Arc<AtomicBool>) -> T + Send + 'static,
) -> (Run, T) {
    let dir = tempfile::tempdir().expect("tempdir");
    let traj = trajectory(dir.path());
    let mcap = dir.path().join("run.mcap");
    let done = Arc::new(AtomicBool::new(false));
    let peer_done = Arc::clone(&done);
    let peer = std::thread::spawn(move || peer(peer_done));
    let out = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["run", traj.to_str().expect("utf-8"), "--record"])
        .arg(&mcap)
        .args(["--camera", "none"])
        .args(devices)
        .args(["--plain", "--config", SHARED_VM_LAB])
        .stdin(Stdio::null())
        .output()
        .expect("run hitl");
    done.store(true, Ordering::Release);
    let got = peer.join().expect("the peer thread");
    let rec = read_recording(&mcap).unwrap_or_else(|e| {
        panic!(
            "the recording stays readable: {e}\n{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (Run { out, rec, traj, _dir: dir }, got)
}

// ---------------------------------------------------------------------------------------------
// DMX: the widget peer (tests/serial_peers) decodes Enttec label-6 messages.

#[test]
fn dmx_levels_follow_the_light_schedule() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let peer = PtyPeer::new();
    let light = format!("dmx:{}", peer.path);
    let (run, frames) = run_with_peer(&light, move |done| dmx_peer(peer, None, done));
    assert_eq!(run.code(), 0, "{}", run.text());
    // Dark from opening, then 0.2, 0.6 and 1.0 of 255, rounded: 51, 153, 255.
    assert_eq!(changes(&frames), vec![0, 51, 153, 255], "{}", run.text());
    // The 0.6 step lasts the schedule's second (at 250 Hz, within DMX's 25 ms refresh).
    let first = |v: u8| frames.iter().find(|f| f.1 == v).map(|f| f.0).expect("level seen");
    let held = first(255).duration_since(first(153)).as_secs_f64();
    assert!((0.85..=1.15).contains(&held), "0.6 held for {held} s");
    // The widget keeps receiving frames for the whole run (the refresh task did not die).
    let span = frames.last().expect("frames").0.duration_since(frames[0].0).as_secs_f64();
    assert!(frames.len() as f64 >= span / 0.05, "{} frames in {span} s", frames.len());
    let levels: Vec<f32> = run.rec.lights.iter().map(|l| l.level).collect();
    assert_eq!(levels, vec![0.2, 0.6, 1.0], "recorded light levels");
}

#[test]
fn a_dmx_widget_that_goes_away_stops_the_run_with_exit_5() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let peer = PtyPeer::new();
    let light = format!("dmx:{}", peer.path);
    let (run, frames) = run_with_peer(&light, move |done| dmx_peer(peer, Some(153), done));
    assert!(frames.iter().any(|f| f.1 == 153), "the peer saw the 0.6 step");
    assert_eq!(run.code(), 5, "{}", run.text());
    assert!(run.has_event("device-fault"), "{:?}", run.rec.events);
    assert!(
        run.rec
            .events
            .iter()
            .any(|e| e.detail.contains("the light failed") && e.detail.contains("DMX light on")),
        "an event names the light: {:?}",
        run.rec.events
    );
    assert!(run.stop_setpoints() > 0, "a controlled stop: {}", run.text());
    assert!(run.text().contains("controlled stop completed"), "{}", run.text());
    let last = run.rec.setpoints.last().expect("setpoints");
    assert!(last.qd.iter().all(|v| v.abs() < 1e-9), "the stop ends at rest");
    assert!(run.rec.end.as_ref().is_some_and(|e| e.complete), "the file has its footer");
}

// ---------------------------------------------------------------------------------------------
// The trigger box: the peer speaks protocol 2 (answers `V`, sends its banner first).

/// What the box does once the level has reached 0.6 (one second into playback).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Then {
    Nothing,
    OpenDoor,
    PressEStop,
    FallSilent,
    SendError,
}

/// What the box received.
#[derive(Debug, Default)]
struct BoxLog {
    levels: Vec<u16>,
    fires: Vec<(u64, u8)>,
    /// The fire time each `F` was acknowledged with, on the box's clock (us).
    fire_us: Vec<u64>,
}

fn box_peer(peer: PtyPeer, then: Then, done: Arc<AtomicBool>) -> BoxLog {
    box_peer_with(peer, then, done, |log, _| log.levels.contains(&600))
}

/// The box peer, acting `then` once `act(log, time since the first fire)` holds.
fn box_peer_with(
    mut peer: PtyPeer,
    then: Then,
    done: Arc<AtomicBool>,
    act: impl Fn(&BoxLog, Duration) -> bool,
) -> BoxLog {
    let start = Instant::now();
    let mut first_fire: Option<Instant> = None;
    let us = || start.elapsed().as_micros() as u64;
    let mut log = BoxLog::default();
    let (mut estop, mut door, mut silent, mut acted) = (false, false, false, false);
    let mut line = Vec::new();
    let mut last_inputs: Option<Instant> = None;
    // A box starting: its banner (ignored by the driver before its ping is answered).
    peer.write(b"# hitl-trigger-box 0.1.0 protocol 2 reset=power\n");
    while !done.load(Ordering::Acquire) {
        for b in peer.read_some(1, Duration::from_millis(5)) {
            if b != b'\n' {
                line.push(b);
                continue;
            }
            let text = String::from_utf8(std::mem::take(&mut line)).expect("ASCII from the host");
            if text.is_empty() {
                continue; // the host's `\n` after opening: ignored (protocol 2)
            }
            let f: Vec<&str> = text.split(' ').collect();
            assert!(text.len() < 64, "line within 64 bytes: {text:?}");
            match f[0] {
                "P" | "S" | "V" => {}
                "L" => log.levels.push(f[2].parse().expect("permille")),
                "F" => log.fires.push((f[2].parse().expect("tick"), f[3].parse().expect("mask"))),
                other => panic!("unknown command {other:?} in {text:?}"),
            }
            let at = us();
            if f[0] == "F" {
                log.fire_us.push(at);
                first_fire.get_or_insert_with(Instant::now);
            }
            if f[0] == "V" {
                peer.write(format!("V {} {at} 2 0.1.0\n", f[1]).as_bytes());
            } else {
                peer.write(format!("A {} {at}\n", f[1]).as_bytes());
            }
        }
        let since_first_fire = first_fire.map_or(Duration::ZERO, |t| t.elapsed());
        if !acted && act(&log, since_first_fire) {
            acted = true;
            match then {
                Then::Nothing => {}
                Then::OpenDoor => door = true,
                Then::PressEStop => estop = true,
                Then::FallSilent => silent = true,
                Then::SendError => peer.write(b"E 0 4\n"),
            }
            last_inputs = None;
        }
        // Inputs every 20 ms (the protocol's limit is 50 ms), and at once on a change.
        if !silent && last_inputs.is_none_or(|t| t.elapsed() >= Duration::from_millis(20)) {
            peer.write(format!("I {} {} {}\n", us(), u8::from(estop), u8::from(door)).as_bytes());
            last_inputs = Some(Instant::now());
        }
    }
    log
}

fn box_run(then: Then) -> (Run, BoxLog) {
    let peer = PtyPeer::new();
    let light = format!("trigger:{}", peer.path);
    run_with_peer(&light, move |done| box_peer(peer, then, done))
}

#[test]
fn the_trigger_box_follows_the_light_schedule_and_fires_at_the_capture_ticks() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, log) = box_run(Then::Nothing);
    assert_eq!(run.code(), 0, "{}", run.text());
    assert_eq!(log.levels, vec![200, 600, 1000], "L lines");
    let fired: Vec<u64> = log.fires.iter().map(|f| f.0).collect();
    assert_eq!(fired, run.capture_ticks(), "F lines at the capture ticks");
    assert!(log.fires.iter().all(|f| f.1 == 1), "the camera line only: {:?}", log.fires);
    // Each acknowledged fire is recorded with the box's own fire time.
    let recorded: Vec<(u64, u64)> =
        run.rec.trigger_fired.iter().map(|m| (m.tick, m.device_us)).collect();
    let acked: Vec<(u64, u64)> = fired.iter().copied().zip(log.fire_us.iter().copied()).collect();
    assert_eq!(recorded, acked, "/trigger/fired");
    assert!(run.rec.events.is_empty(), "{:?}", run.rec.events);
}

#[test]
fn the_door_opening_on_the_trigger_box_stops_the_run_with_exit_4() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, _) = box_run(Then::OpenDoor);
    assert_eq!(run.code(), 4, "{}", run.text());
    assert!(run.has_event("door-open"), "{:?}", run.rec.events);
    assert!(run.stop_setpoints() > 0, "a controlled stop: {}", run.text());
    assert!(run.text().contains("controlled stop completed"), "{}", run.text());
}

#[test]
fn the_estop_on_the_trigger_box_holds_with_exit_4() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, _) = box_run(Then::PressEStop);
    assert_eq!(run.code(), 4, "{}", run.text());
    assert!(run.has_event("e-stop"), "{:?}", run.rec.events);
    assert_eq!(run.stop_setpoints(), 0, "a hold sends no stop trajectory");
    assert!(run.text().contains("arm told to hold"), "{}", run.text());
}

#[test]
fn a_trigger_box_that_stops_reporting_its_inputs_is_a_device_fault_with_exit_5() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, _) = box_run(Then::FallSilent);
    assert_eq!(run.code(), 5, "{}", run.text());
    assert!(run.has_event("device-fault"), "{:?}", run.rec.events);
    assert!(run.text().contains("input reports (e-stop, door) are stale"), "{}", run.text());
    assert!(run.stop_setpoints() > 0, "a controlled stop: {}", run.text());
}

#[test]
fn an_error_line_from_the_trigger_box_is_a_device_fault_with_exit_5() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, _) = box_run(Then::SendError);
    assert_eq!(run.code(), 5, "{}", run.text());
    assert!(run.has_event("device-fault"), "{:?}", run.rec.events);
    assert!(run.text().contains("trigger box reported an error"), "{}", run.text());
    assert!(run.stop_setpoints() > 0, "a controlled stop: {}", run.text());
}

/// `--trigger trigger:BOX --light dmx:WIDGET`: a lab whose Sun is a DMX fixture still fires its
/// camera from the box and reads the box's inputs; the box's light output is never driven.
fn box_beside_dmx(then: Then) -> (Run, BoxLog, Vec<(Instant, u8)>) {
    let box_pty = PtyPeer::new();
    let widget = PtyPeer::new();
    let trigger = format!("trigger:{}", box_pty.path);
    let light = format!("dmx:{}", widget.path);
    let (run, (log, frames)) =
        run_with_devices(&["--trigger", &trigger, "--light", &light], move |done| {
            let widget_done = Arc::clone(&done);
            let dmx = std::thread::spawn(move || dmx_peer(widget, None, widget_done));
            // The box acts on its own clock here: it never sees a level, so it acts 1.2 s in.
            let log = box_peer_timed(box_pty, then, done);
            (log, dmx.join().expect("the widget thread"))
        });
    (run, log, frames)
}

/// [`box_peer`] for a box that is not the light: it acts `then` 1.2 s after the first fire.
fn box_peer_timed(peer: PtyPeer, then: Then, done: Arc<AtomicBool>) -> BoxLog {
    box_peer_with(peer, then, done, |log, since_first_fire| {
        !log.fires.is_empty() && since_first_fire >= Duration::from_millis(1200)
    })
}

#[test]
fn a_trigger_box_beside_a_dmx_light_fires_the_camera_while_the_widget_follows_the_schedule() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, log, frames) = box_beside_dmx(Then::Nothing);
    assert_eq!(run.code(), 0, "{}", run.text());
    let fired: Vec<u64> = log.fires.iter().map(|f| f.0).collect();
    assert_eq!(fired, run.capture_ticks(), "F lines at the capture ticks");
    assert!(log.levels.is_empty(), "the box's light is not driven: {:?}", log.levels);
    assert_eq!(changes(&frames), vec![0, 51, 153, 255], "{}", run.text());
    assert_eq!(run.rec.trigger_fired.len(), fired.len(), "/trigger/fired");
    let meta = &run.rec.metadata["run"]["config"];
    assert!(meta.contains("\"trigger\":\"trigger:"), "the run records its trigger: {meta}");
}

#[test]
fn the_door_on_a_trigger_box_beside_a_dmx_light_stops_the_run_with_exit_4() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, _, _) = box_beside_dmx(Then::OpenDoor);
    assert_eq!(run.code(), 4, "{}", run.text());
    assert!(run.has_event("door-open"), "{:?}", run.rec.events);
}

#[test]
fn a_mistyped_device_choice_fails_with_exit_2_before_anything_loads() {
    // The trajectory does not exist: had anything been loaded, the error would name the file.
    for (flag, value) in [
        ("--camera", "orbec"),
        ("--light", "dmx"),
        ("--light", "dmx:/dev/null,addr=600"),
        ("--perception", "icpp"),
        ("--trigger", "dmx:/dev/ttyUSB0"),
        ("--trigger", "trigger:"),
        ("--rt-priority", "100"),
        ("--stub-fault", "estopp@1"),
    ] {
        let out = common::hitl(&["run", "/nonexistent/traj.npz", flag, value]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(&format!("invalid value '{value}' for '{flag}")), "{err}");
        assert!(!err.contains("traj.npz"), "refused before loading: {err}");
    }
}
