//! `hitl probe` commissioning the camera and the light, through the binary: the Orbbec SDK double
//! (`tests/orbbec_fake`, a stand-in libOrbbecSDK.so) for the camera, pseudo-terminal peers for
//! the trigger box and the DMX widget. What it prints (serial, firmware, profiles, intrinsics and
//! distortion, the sync mode found, a crashed run's leftover), `--camera orbbec@SERIAL`,
//! `--test-fire N` with the camera (frames, misses, latency; the camera written back after),
//! `--test-levels`, and the exit codes.

#[path = "../drivers/tests/light_pty/mod.rs"]
mod light_pty;
mod orbbec_fake;

use hitl_drivers::orbbec::sdk_clock_now_us;
use light_pty::PtyPeer;
use orbbec_fake::{FakeOrbbec, FACTORY_SYNC};
use std::io::Write as _;
use std::process::{Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One probe at a time: `--test-fire` answers the trigger box within its 50 ms deadline and
/// converts 1280x800 frames, which parallel probes on a 2-core machine can starve.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

fn probe(fake: &FakeOrbbec, args: &[&str]) -> Output {
    fake.hitl().arg("probe").args(args).stdin(Stdio::null()).output().expect("run hitl probe")
}

#[test]
fn probe_prints_what_commissioning_needs_of_the_camera() {
    let _one = one_at_a_time();
    let fake = FakeOrbbec::new(&[("CP1E54200057", 0x0840, "1.0.80")]);
    let out = probe(&fake, &["--camera"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    for want in [
        "serial CP1E54200057 pid 0x0840 firmware 1.0.80 (Orbbec SDK 2.9.3)",
        "firmware new enough for the sync voltage setting (needs >= 1.0.76); the camera offers it",
        "sync documented: primary, secondary-synced, software-triggering, hardware-triggering",
        "colour: 1280x800 RGB(22) @30 fps",
        "depth: 1280x800 Y16(8) @30 fps",
        "sync mode found: free-run, 1 frame(s) per trigger, trigger out on (+0 us)",
        "intrinsics 1280x800 colour: fx 960.000 fy 960.000 cx 640.000 cy 400.000",
        "distortion Brown-Conrady k [0.125, -0.25, 0.0, 0.0, 0.0, 0.0] p1 0.001 p2 -0.002",
        "intrinsics 64x40 depth: fx 48.000",
        "every named device answered",
    ] {
        assert!(all.contains(want), "missing {want:?} in:\n{all}");
    }
    assert!(!all.contains("LEFTOVER") && !all.contains("waits for triggers"), "{all}");
    assert_eq!(fake.sync("CP1E54200057"), FACTORY_SYNC, "probe changes nothing");
}

#[test]
fn old_firmware_and_a_camera_left_waiting_for_triggers_are_said() {
    let _one = one_at_a_time();
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.70")]);
    fake.set_sync("CP1", "64 0 0 0 0 0 1");
    let all = text(&probe(&fake, &["--camera"]));
    assert!(all.contains("firmware too old for the sync voltage setting"), "{all}");
    assert!(all.contains("the camera does not offer it"), "{all}");
    assert!(all.contains("sync mode found: hardware-triggering"), "{all}");
    assert!(all.contains("the camera waits for triggers: other tools get no frames"), "{all}");
}

#[test]
fn a_crashed_runs_leftover_is_reported() {
    let _one = one_at_a_time();
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80")]);
    fake.set_sync("CP1", "32 0 0 0 0 0 1");
    let marker = fake.marker("CP1");
    std::fs::create_dir_all(marker.parent().expect("dir")).expect("mkdir");
    std::fs::write(
        &marker,
        "serial=CP1\npid=4242\nwritten_unix_s=1\nsync_mode=1\ndepth_delay_us=0\n\
         color_delay_us=0\ntrigger_to_image_delay_us=0\ntrigger_out_enable=1\n\
         trigger_out_delay_us=0\nframes_per_trigger=1\nexposure_reference=0\n",
    )
    .expect("state file");
    let out = probe(&fake, &["--camera"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("sync mode found: software-triggering"), "{all}");
    assert!(
        all.contains(
            "LEFTOVER: a run ended without writing the camera's configuration back (process 4242"
        ),
        "{all}"
    );
    assert!(all.contains("records what it had before (free-run"), "{all}");
}

#[test]
fn a_camera_is_named_by_serial_and_an_absent_one_is_exit_5() {
    let _one = one_at_a_time();
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80"), ("CP2", 0x0842, "1.0.80")]);
    let out = probe(&fake, &["--camera", "orbbec@cp2"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(text(&out).contains("serial CP2 pid 0x0842"), "{}", text(&out));
    let out = probe(&fake, &["--camera", "orbbec@CP9"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("no Orbbec camera with serial CP9: connected: CP1, CP2"), "{all}");
    let none = FakeOrbbec::new(&[]);
    let out = probe(&none, &["--camera"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("cameras: none found"), "{all}");
    assert!(all.contains("probe: camera did not answer: no Orbbec camera connected"), "{all}");
}

/// A trigger box on a pty (protocol 2): answers every command; each `F` (fire) also pulses the
/// fake cameras' sync input through `pulses` when `wired` (at the moment the box answers with
/// its fire time); inputs every 20 ms.
fn trigger_box(mut peer: PtyPeer, pulses: std::path::PathBuf, wired: bool, done: Arc<AtomicBool>) {
    // Read and write: opening a FIFO for writing alone would wait for a reader.
    let mut fifo = std::fs::OpenOptions::new().read(true).write(true).open(pulses).expect("pulses");
    let start = Instant::now();
    let mut line = Vec::new();
    let mut last = Instant::now() - Duration::from_secs(1);
    while !done.load(Ordering::Acquire) {
        for b in peer.read_some(1, Duration::from_millis(2)) {
            if b != b'\n' {
                line.push(b);
                continue;
            }
            let text = String::from_utf8(std::mem::take(&mut line)).expect("ASCII");
            if text.is_empty() {
                continue;
            }
            let seq = text.split(' ').nth(1).unwrap_or("0").to_string();
            let us = start.elapsed().as_micros();
            if text.starts_with("V ") {
                peer.write(format!("V {seq} {us} 2 0.1.0\n").as_bytes());
                continue;
            }
            if text.starts_with("F ") && wired {
                // The pulse, at its time on the SDK's clock (CLOCK_MONOTONIC, us).
                fifo.write_all(&sdk_clock_now_us().to_le_bytes()).expect("pulse");
            }
            peer.write(format!("A {seq} {us}\n").as_bytes());
        }
        if last.elapsed() >= Duration::from_millis(20) {
            peer.write(format!("I {} 0 0\n", start.elapsed().as_micros()).as_bytes());
            last = Instant::now();
        }
    }
}

fn test_fire(wired: bool, n: &str) -> (Output, FakeOrbbec) {
    let fake = FakeOrbbec::new(&[("CP1", 0x0840, "1.0.80")]);
    // Small frames: an unoptimised build converting 1280x800 framesets on a loaded 2-core
    // machine can keep the trigger box's answers past their 50 ms deadline.
    fake.sizes(&[(64, 40)]);
    let pulses = fake.pulses();
    let peer = PtyPeer::new();
    let path = peer.path.clone();
    let done = Arc::new(AtomicBool::new(false));
    let stop = Arc::clone(&done);
    let thread = std::thread::spawn(move || trigger_box(peer, pulses, wired, stop));
    let out =
        probe(&fake, &["--camera", "--trigger", &format!("trigger:{path}"), "--test-fire", n]);
    done.store(true, Ordering::Release);
    thread.join().expect("peer");
    (out, fake)
}

#[test]
fn test_fire_counts_the_cameras_frames_and_times_them_then_writes_the_camera_back() {
    let _one = one_at_a_time();
    let (out, fake) = test_fire(true, "5");
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("test fire: 5 pulse(s) 100 ms apart"), "{all}");
    assert!(all.contains("hardware triggering at 64x40 RGB(22) @30 fps"), "{all}");
    assert!(all.contains("test fire: 5 of 5 frames received, 0 missed"), "{all}");
    assert!(
        all.contains("trigger to frame timestamp (exposure (the SDK's global timestamp)): p50"),
        "{all}"
    );
    assert!(all.contains("configuration written back (free-run"), "{all}");
    assert_eq!(fake.sync("CP1"), FACTORY_SYNC, "the camera as found; log:\n{}", fake.log());
    assert!(
        fake.log().contains("sync CP1 64 out 0"),
        "hardware triggering, trigger out off: {}",
        fake.log()
    );
    assert!(!fake.marker("CP1").exists(), "state file removed");
}

#[test]
fn test_fire_with_the_line_unwired_is_exit_5_and_the_camera_is_still_written_back() {
    let _one = one_at_a_time();
    let (out, fake) = test_fire(false, "2");
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("0 of 2 frames received, 2 missed"), "{all}");
    assert!(all.contains("is the trigger box's camera line wired"), "{all}");
    assert_eq!(fake.sync("CP1"), FACTORY_SYNC, "log:\n{}", fake.log());
}

#[test]
fn test_levels_steps_the_dmx_light_through_its_levels() {
    let _one = one_at_a_time();
    let mut peer = PtyPeer::new();
    let path = peer.path.clone();
    let done = Arc::new(AtomicBool::new(false));
    let stop = Arc::clone(&done);
    // Answer the parameters request (label 3), decode Enttec "send DMX" frames (0x7E, 6, len
    // LSB, MSB, start code, channels.., 0xE7) and keep each change of channel 1.
    let thread = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let mut seen: Vec<u8> = Vec::new();
        while !stop.load(Ordering::Acquire) {
            bytes.extend(peer.read_some(600, Duration::from_millis(5)));
            while let Some(s) = bytes.iter().position(|b| *b == 0x7E) {
                if bytes.len() < s + 6 {
                    break;
                }
                let len = usize::from(bytes[s + 2]) | usize::from(bytes[s + 3]) << 8;
                if bytes.len() < s + 5 + len {
                    break;
                }
                if bytes[s + 1] == 3 {
                    // The probe's parameters request: answer as a widget does.
                    peer.write(&[0x7E, 3, 5, 0, 0x44, 0x01, 9, 1, 40, 0xE7]);
                }
                if bytes[s + 1] == 6 && len >= 2 && seen.last() != Some(&bytes[s + 5]) {
                    seen.push(bytes[s + 5]);
                }
                bytes.drain(..s + 5 + len);
            }
        }
        seen
    });
    let fake = FakeOrbbec::new(&[]);
    let out = probe(&fake, &["--light", &format!("dmx:{path}"), "--test-levels"]);
    done.store(true, Ordering::Release);
    let seen = thread.join().expect("peer");
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("a run sends level changes 25 ms early"), "{all}");
    assert!(all.contains("level 0.75 at +"), "{all}");
    assert!(all.contains("followed every step (ends dark)"), "{all}");
    assert_eq!(seen, vec![0, 64, 128, 191, 255, 0], "channel 1 as the widget received it");
}

#[test]
fn test_levels_without_a_light_is_bad_input() {
    let _one = one_at_a_time();
    let out = probe(&FakeOrbbec::new(&[]), &["--test-levels"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("--test-levels needs a light"), "{}", text(&out));
}
