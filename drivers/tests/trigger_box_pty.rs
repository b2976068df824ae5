//! The trigger-box driver against a pty peer that plays the box: fires acknowledged with device
//! timestamps, input reports, light commands, and garbage / silence / unplug as faults.

#![allow(clippy::unwrap_used)]

mod light_pty;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use hitl_drivers::light::{TriggerBox, TriggerBoxConfig};
use hitl_hal::{
    Clock, Error, ErrorKind, Inputs, Lifecycle, Light, MonotonicClock, Trigger, TriggerLines,
};
use light_pty::{eventually, PtyPeer};

/// What the simulated box does; tests flip these while it runs.
#[derive(Default)]
struct Behaviour {
    ack_fires: AtomicBool,
    ack_other: AtomicBool,
    send_inputs: AtomicBool,
    estop: AtomicBool,
    door: AtomicBool,
    unplug: AtomicBool,
    stop: AtomicBool,
    /// Raw bytes to send once.
    inject: Mutex<Vec<u8>>,
    /// Lines received from the host.
    received: Mutex<Vec<String>>,
    /// The device time sent in the ack of each seq.
    acked: Mutex<HashMap<u32, u64>>,
}

/// The box's clock: microseconds since the peer started, plus 5 s (a clock of its own).
const DEVICE_EPOCH_US: u128 = 5_000_000;

struct BoxPeer {
    path: String,
    b: Arc<Behaviour>,
    thread: Option<JoinHandle<()>>,
}

impl BoxPeer {
    fn start() -> Self {
        let b = Arc::new(Behaviour::default());
        b.ack_fires.store(true, Ordering::SeqCst);
        b.ack_other.store(true, Ordering::SeqCst);
        b.send_inputs.store(true, Ordering::SeqCst);
        let mut pty = PtyPeer::new();
        let path = pty.path.clone();
        let bb = Arc::clone(&b);
        let thread = std::thread::spawn(move || {
            let mut line = Vec::new();
            let mut buf = [0u8; 256];
            let mut last_inputs = std::time::Instant::now() - Duration::from_secs(1);
            let t0 = std::time::Instant::now();
            while !bb.stop.load(Ordering::SeqCst) {
                if bb.unplug.load(Ordering::SeqCst) {
                    return; // drops the master: the host sees a hang-up
                }
                let inject = std::mem::take(&mut *bb.inject.lock().unwrap());
                if !inject.is_empty() {
                    pty.write(&inject);
                }
                if bb.send_inputs.load(Ordering::SeqCst)
                    && last_inputs.elapsed() >= Duration::from_millis(20)
                {
                    let us = t0.elapsed().as_micros();
                    let e = u8::from(bb.estop.load(Ordering::SeqCst));
                    let d = u8::from(bb.door.load(Ordering::SeqCst));
                    pty.write(format!("I {us} {e} {d}\n").as_bytes());
                    last_inputs = std::time::Instant::now();
                }
                let n = pty.try_read(&mut buf);
                for &c in &buf[..n] {
                    if c != b'\n' {
                        line.push(c);
                        continue;
                    }
                    let text = String::from_utf8(std::mem::take(&mut line)).unwrap();
                    let mut f = text.split(' ');
                    let kind = f.next().unwrap_or_default().to_string();
                    let seq: u32 = f.next().and_then(|s| s.parse().ok()).unwrap_or(0);
                    bb.received.lock().unwrap().push(text);
                    let ack = if kind == "F" {
                        bb.ack_fires.load(Ordering::SeqCst)
                    } else {
                        bb.ack_other.load(Ordering::SeqCst)
                    };
                    if ack {
                        let device_us = u64::try_from(t0.elapsed().as_micros() + DEVICE_EPOCH_US)
                            .unwrap_or(u64::MAX);
                        bb.acked.lock().unwrap().insert(seq, device_us);
                        pty.write(format!("A {seq} {device_us}\n").as_bytes());
                    }
                }
            }
        });
        Self { path, b, thread: Some(thread) }
    }

    fn acked(&self, seq: u32) -> Option<u64> {
        self.b.acked.lock().unwrap().get(&seq).copied()
    }

    fn received(&self) -> Vec<String> {
        self.b.received.lock().unwrap().clone()
    }

    fn inject(&self, bytes: &[u8]) {
        self.b.inject.lock().unwrap().extend_from_slice(bytes);
    }
}

impl Drop for BoxPeer {
    fn drop(&mut self) {
        self.b.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn config() -> TriggerBoxConfig {
    // Deadlines with room for a loaded CI machine; the fault tests wait up to 3 s.
    TriggerBoxConfig {
        ack_timeout: Duration::from_millis(300),
        inputs_stale_after: Duration::from_millis(500),
        ..TriggerBoxConfig::default()
    }
}

async fn open(peer: &BoxPeer) -> TriggerBox {
    TriggerBox::open(&peer.path, config(), MonotonicClock::new()).await.expect("open trigger box")
}

const BOTH: TriggerLines = TriggerLines { camera: true, light: true };
const CAMERA: TriggerLines = TriggerLines { camera: true, light: false };

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fires_are_acknowledged_with_device_timestamps() {
    let peer = BoxPeer::start();
    let clock = MonotonicClock::new();
    let mut tb = TriggerBox::open(&peer.path, config(), clock).await.expect("open trigger box");
    assert_eq!(peer.received().first().map(String::as_str), Some("P 1"), "open pings first");

    let fired_ns = clock.now_ns();
    tb.fire(7, BOTH).expect("fire");
    let r = eventually(Duration::from_secs(2), || tb.poll_fired().expect("no fault"))
        .await
        .expect("ack");
    assert_eq!(r.tick, 7);
    assert_eq!(Some(r.device_us), peer.acked(2), "the ack's device time of command seq 2");
    assert!(r.acked_ns > fired_ns);
    // The box's time maps onto the host clock between the fire call and the ack's arrival.
    let host = tb.device_to_host_ns(r.device_us).expect("offset estimated from acks");
    let slack = tb.clock_uncertainty_ns().expect("uncertainty") + 2_000_000;
    assert!(
        host + slack >= fired_ns && host <= r.acked_ns + slack,
        "mapped {host} outside [{fired_ns}, {}] +- {slack}",
        r.acked_ns
    );
    assert!(peer.received().contains(&"F 2 7 3".to_string()), "{:?}", peer.received());

    tb.fire(8, CAMERA).expect("fire");
    let r = eventually(Duration::from_secs(2), || tb.poll_fired().expect("no fault"))
        .await
        .expect("ack");
    assert_eq!((r.tick, Some(r.device_us)), (8, peer.acked(3)));
    assert!(peer.received().contains(&"F 3 8 1".to_string()), "{:?}", peer.received());
    assert_eq!(tb.poll_fired().expect("no fault"), None);

    let e = tb.fire(9, TriggerLines::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::InvalidRequest);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn inputs_follow_the_box_reports() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    let s = tb.read().expect("inputs");
    assert!(!s.estop_pressed && !s.door_open);
    peer.b.estop.store(true, Ordering::SeqCst);
    eventually(Duration::from_secs(2), || tb.read().expect("inputs").estop_pressed.then_some(()))
        .await
        .expect("e-stop press seen");
    peer.b.door.store(true, Ordering::SeqCst);
    peer.b.estop.store(false, Ordering::SeqCst);
    let s = eventually(Duration::from_secs(2), || {
        let s = tb.read().expect("inputs");
        (s.door_open && !s.estop_pressed).then_some(s)
    })
    .await
    .expect("door open seen");
    assert!(s.door_open);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn light_level_and_strobe_become_commands() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    tb.set_level(0.5).expect("level");
    tb.set_level(0.25).expect("level");
    tb.strobe(1.0, 2000).expect("strobe");
    let lines = eventually(Duration::from_secs(2), || {
        let r = peer.received();
        r.iter().any(|l| l.starts_with("S ")).then_some(r)
    })
    .await
    .expect("strobe sent");
    let levels: Vec<&str> = lines
        .iter()
        .filter(|l| l.starts_with("L "))
        .map(|l| l.rsplit(' ').next().unwrap())
        .collect();
    assert_eq!(levels.last(), Some(&"250"), "latest level wins: {lines:?}");
    let strobe = lines.iter().find(|l| l.starts_with("S ")).unwrap();
    assert!(strobe.ends_with(" 1000 2000"), "{strobe}");
    // The level is sent once, not on every poll.
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(peer.received().iter().filter(|l| l.ends_with(" 250")).count(), 1);
    assert!(tb.fault().is_none());
}

async fn expect_fault(tb: &mut TriggerBox, kind: ErrorKind) -> String {
    // Probe without queuing anything (acks that arrived before the fault are drained first).
    let e = eventually(Duration::from_secs(3), || tb.poll_fired().err())
        .await
        .unwrap_or_else(|| panic!("expected a {kind} fault"));
    assert_eq!(e.kind(), kind, "{e}");
    // Sticky: every later call reports it too.
    assert_eq!(tb.fire(1, CAMERA).unwrap_err().kind(), kind);
    assert_eq!(tb.read().unwrap_err().kind(), kind);
    assert_eq!(tb.set_level(0.5).unwrap_err().kind(), kind);
    assert_eq!(tb.poll_fired().unwrap_err().kind(), kind);
    e.to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_line_is_a_protocol_fault() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.inject(b"hello there\n");
    let msg = expect_fault(&mut tb, ErrorKind::Protocol).await;
    assert!(msg.contains("not part of the protocol"), "{msg}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn over_long_line_is_a_protocol_fault() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.inject(&[b'7'; 500]);
    let msg = expect_fault(&mut tb, ErrorKind::Protocol).await;
    assert!(msg.contains("over-long"), "{msg}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ack_for_an_unsent_command_is_a_protocol_fault() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.inject(b"A 999 5\n");
    expect_fault(&mut tb, ErrorKind::Protocol).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn box_error_line_is_a_device_fault() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.inject(b"E 0 4\n");
    expect_fault(&mut tb, ErrorKind::DeviceFault).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn missing_ack_is_a_timeout() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.b.ack_fires.store(false, Ordering::SeqCst);
    tb.fire(3, CAMERA).expect("fire queued");
    let msg = expect_fault(&mut tb, ErrorKind::Timeout).await;
    assert!(msg.contains("acknowledge"), "{msg}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stale_inputs_are_a_timeout() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    tb.read().expect("fresh at first");
    peer.b.send_inputs.store(false, Ordering::SeqCst);
    let e = eventually(Duration::from_secs(3), || tb.read().err()).await.expect("stale inputs");
    assert_eq!(e.kind(), ErrorKind::Timeout, "{e}");
    assert!(e.to_string().contains("stale"), "{e}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unplug_is_disconnected() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.b.unplug.store(true, Ordering::SeqCst);
    let msg = expect_fault(&mut tb, ErrorKind::Disconnected).await;
    assert!(msg.contains("unplugged"), "{msg}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_box_fails_to_open_naming_the_port() {
    let peer = BoxPeer::start();
    peer.b.ack_other.store(false, Ordering::SeqCst);
    peer.b.send_inputs.store(false, Ordering::SeqCst);
    let cfg = TriggerBoxConfig { open_timeout: Duration::from_millis(300), ..config() };
    let Err(e) = TriggerBox::open(&peer.path, cfg, MonotonicClock::new()).await else {
        panic!("a silent box must not open");
    };
    assert!(matches!(e.kind(), ErrorKind::Timeout), "{e}");
    assert!(e.to_string().contains(&peer.path), "{e}");
}

/// `stop` writes what the tick queued, ends the task and lets go of the port (it can be opened
/// again at once); stopping is not a fault, for this handle or its clones.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stop_writes_what_is_queued_and_releases_the_port() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    let mut inputs = tb.clone();
    tb.set_level(0.25).expect("level");
    let mut stopping = tb.clone();
    let r = tokio::task::spawn_blocking(move || stopping.stop()).await.unwrap();
    r.expect("stop finishes in time");
    let sent = eventually(Duration::from_secs(2), || {
        peer.received().iter().any(|l| l.starts_with("L ") && l.ends_with(" 250")).then_some(())
    })
    .await;
    assert!(
        sent.is_some(),
        "the queued level went out before the port closed: {:?}",
        peer.received()
    );
    tb.health().expect("a stopped box is not a faulty one");
    assert!(inputs.health().is_ok(), "nor are its clones");
    let again = TriggerBox::open(&peer.path, config(), MonotonicClock::new()).await;
    assert!(again.is_ok(), "the port is free after stop: {:?}", again.err());
}

/// A box opened in a runtime that is then dropped (the bug behind issue 12) reports it at the
/// next call from the tick instead of going silent.
#[test]
fn a_box_whose_runtime_is_gone_reports_it_at_the_next_call() {
    let peer = BoxPeer::start();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let mut tb = rt
        .block_on(TriggerBox::open(&peer.path, config(), MonotonicClock::new()))
        .expect("open trigger box");
    drop(rt);
    let e = tb.health().unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Disconnected, "{e}");
    assert!(tb.read().is_err(), "the inputs are no longer known");
}
