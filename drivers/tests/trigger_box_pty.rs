//! The trigger-box driver against a pty peer that plays the box (protocol 2): fires acknowledged
//! with device timestamps and mapped onto the host's clock, input reports, light commands, the
//! version check, banners and notices, keep-alives, busy answers retried, and garbage / silence /
//! unplug / restart as faults.

#![allow(clippy::unwrap_used)]

mod light_pty;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU16, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use hitl_drivers::light::protocol::ResetCause;
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
    /// The protocol `V` answers with; 0: answer `E <seq> 2` (a protocol-1 box).
    protocol: AtomicU16,
    /// Answer this many `F` lines with `E <seq> 3` (busy).
    busy_fires: AtomicU32,
    /// Drop this many commands without an answer, then say so with `E 0 3`.
    drop_commands: AtomicU32,
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
        Self::start_with(|_| {})
    }

    /// A peer whose behaviour is set up by `setup` before it sends anything (e.g. a banner to
    /// inject first, or the version it answers with).
    fn start_with(setup: impl FnOnce(&Behaviour)) -> Self {
        let b = Arc::new(Behaviour::default());
        b.protocol.store(2, Ordering::SeqCst);
        b.ack_fires.store(true, Ordering::SeqCst);
        b.ack_other.store(true, Ordering::SeqCst);
        b.send_inputs.store(true, Ordering::SeqCst);
        setup(&b);
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
                    if text.is_empty() {
                        continue; // an empty line is ignored, not answered (protocol 2)
                    }
                    let mut f = text.split(' ');
                    let kind = f.next().unwrap_or_default().to_string();
                    let seq: u32 = f.next().and_then(|s| s.parse().ok()).unwrap_or(0);
                    bb.received.lock().unwrap().push(text);
                    let ack = if kind == "F" {
                        bb.ack_fires.load(Ordering::SeqCst)
                    } else {
                        bb.ack_other.load(Ordering::SeqCst)
                    };
                    let take = |n: &AtomicU32| {
                        n.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |v| v.checked_sub(1))
                            .is_ok()
                    };
                    if take(&bb.drop_commands) {
                        if bb.drop_commands.load(Ordering::SeqCst) == 0 {
                            pty.write(b"E 0 3\n");
                        }
                        continue;
                    }
                    if kind == "F" && take(&bb.busy_fires) {
                        pty.write(format!("E {seq} 3\n").as_bytes());
                        continue;
                    }
                    if ack {
                        let device_us = u64::try_from(t0.elapsed().as_micros() + DEVICE_EPOCH_US)
                            .unwrap_or(u64::MAX);
                        bb.acked.lock().unwrap().insert(seq, device_us);
                        let protocol = bb.protocol.load(Ordering::SeqCst);
                        let answer = match (kind.as_str(), protocol) {
                            ("V", 0) => format!("E {seq} 2\n"),
                            ("V", p) => format!("V {seq} {device_us} {p} 0.1.0\n"),
                            _ => format!("A {seq} {device_us}\n"),
                        };
                        pty.write(answer.as_bytes());
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
    let mut tb =
        TriggerBox::open(&peer.path, config(), clock.clone()).await.expect("open trigger box");
    assert_eq!(
        peer.received().get(..2),
        Some(&["P 1".to_string(), "V 2".to_string()][..]),
        "open pings, then asks the version"
    );
    let v = tb.version().expect("version known once open");
    assert_eq!((v.protocol, v.firmware.to_string().as_str()), (2, "0.1.0"));

    let fired_ns = clock.now_ns();
    tb.fire(7, BOTH).expect("fire");
    let r = eventually(Duration::from_secs(2), || tb.poll_fired().expect("no fault"))
        .await
        .expect("ack");
    assert_eq!(r.tick, 7);
    assert_eq!(Some(r.device_us), peer.acked(3), "the ack's device time of command seq 3");
    assert!(r.acked_ns > fired_ns);
    // The box's time maps onto the host clock between the fire call and the ack's arrival,
    // within the mapping's own bound.
    let host = r.host_ns.expect("the fire on the host's clock");
    let err = r.host_error_ns.expect("its bound");
    // The mapping's time, held to the fire's own round trip.
    let mapped = tb.device_to_host_ns(r.device_us).expect("mapping");
    assert!(mapped.abs_diff(host) <= err.max(tb.clock_uncertainty_ns().unwrap_or(0)) + 1_000_000);
    assert!(
        host + err >= fired_ns && host <= r.acked_ns + err,
        "mapped {host} outside [{fired_ns}, {}] +- {err}",
        r.acked_ns
    );
    assert!(err < 2 * (r.acked_ns - fired_ns) + 2_000_000, "bound {err} ns");
    assert!(peer.received().contains(&"F 3 7 3".to_string()), "{:?}", peer.received());

    tb.fire(8, CAMERA).expect("fire");
    let r = eventually(Duration::from_secs(2), || tb.poll_fired().expect("no fault"))
        .await
        .expect("ack");
    assert_eq!((r.tick, Some(r.device_us)), (8, peer.acked(4)));
    assert!(peer.received().contains(&"F 4 8 1".to_string()), "{:?}", peer.received());
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
    // A poll writes the strobe before the level, so wait for both to arrive.
    let lines = eventually(Duration::from_secs(2), || {
        let r = peer.received();
        let level = r.iter().any(|l| l.starts_with("L ") && l.ends_with(" 250"));
        (level && r.iter().any(|l| l.starts_with("S "))).then_some(r)
    })
    .await
    .expect("strobe and level sent");
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
    let cfg = TriggerBoxConfig {
        open_timeout: Duration::from_millis(300),
        start_timeout: Duration::from_millis(300),
        ..config()
    };
    let Err(e) = TriggerBox::open(&peer.path, cfg, MonotonicClock::new()).await else {
        panic!("a silent box must not open");
    };
    assert!(matches!(e.kind(), ErrorKind::Timeout), "{e}");
    assert!(e.to_string().contains(&peer.path), "{e}");
    assert!(e.to_string().contains("not a line from it"), "{e}");
    assert!(peer.received().is_empty(), "nothing written before the box spoke");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_box_that_reports_but_does_not_answer_fails_to_open() {
    let peer = BoxPeer::start();
    peer.b.ack_other.store(false, Ordering::SeqCst);
    let cfg = TriggerBoxConfig {
        open_timeout: Duration::from_millis(300),
        ack_timeout: Duration::from_secs(1),
        ..config()
    };
    let Err(e) = TriggerBox::open(&peer.path, cfg, MonotonicClock::new()).await else {
        panic!("a box that does not answer must not open");
    };
    assert!(matches!(e.kind(), ErrorKind::Timeout), "{e}");
    assert!(e.to_string().contains("no answer to the ping"), "{e}");
}

/// An Uno that resets when its port is opened: silent in its bootloader (longer than the
/// ordinary open timeout), then the banner: nothing may be written before it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn open_waits_for_a_box_that_resets_and_ignores_its_banner() {
    let peer = BoxPeer::start_with(|b| b.send_inputs.store(false, Ordering::SeqCst));
    let b = Arc::clone(&peer.b);
    let path = peer.path.clone();
    let opening = tokio::spawn(async move {
        // The banner comes 0.8 s in; 5 s to see it leaves a loaded machine room.
        let cfg = TriggerBoxConfig {
            open_timeout: Duration::from_millis(500),
            start_timeout: Duration::from_secs(5),
            ..config()
        };
        TriggerBox::open(&path, cfg, MonotonicClock::new()).await
    });
    tokio::time::sleep(Duration::from_millis(800)).await;
    assert!(peer.received().is_empty(), "nothing written to a box in its bootloader");
    // A partial line first (the end of what it sent before): dropped.
    b.inject
        .lock()
        .unwrap()
        .extend_from_slice(b"0 0\n# hitl-trigger-box 0.1.0 protocol 2 reset=external\n");
    b.send_inputs.store(true, Ordering::SeqCst);
    let tb = opening.await.unwrap().expect("opens after the banner");
    assert!(tb.fault().is_none());
    assert_eq!(tb.restart_cause(), None, "a banner before the ping is the box starting");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_banner_after_opening_means_the_box_restarted() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    peer.inject(b"# hitl-trigger-box 0.1.0 protocol 2 reset=watchdog\n");
    let msg = expect_fault(&mut tb, ErrorKind::DeviceFault).await;
    assert!(msg.contains("restarted"), "{msg}");
    assert_eq!(tb.restart_cause(), Some(ResetCause::Watchdog));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn notices_are_ignored_and_host_silence_sends_the_level_again() {
    let peer = BoxPeer::start();
    let mut tb = open(&peer).await;
    tb.set_level(0.5).expect("level");
    eventually(Duration::from_secs(2), || {
        peer.received().iter().any(|l| l.starts_with("L ")).then_some(())
    })
    .await
    .expect("level sent");
    peer.inject(b"# a note for people\n# safe host-silent\n");
    let levels = eventually(Duration::from_secs(2), || {
        let n = peer.received().iter().filter(|l| l.starts_with("L ")).count();
        (n == 2).then_some(n)
    })
    .await;
    assert_eq!(levels, Some(2), "the level again after the box went safe: {:?}", peer.received());
    assert_eq!(tb.host_silent_notices(), 1);
    assert!(tb.fault().is_none(), "notices are not faults");
    tb.read().expect("inputs");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keepalive_pings_when_nothing_else_is_written() {
    let peer = BoxPeer::start();
    let tb = open(&peer).await;
    tokio::time::sleep(Duration::from_millis(1100)).await;
    let pings = peer.received().iter().filter(|l| l.starts_with("P ")).count();
    // The open's ping, then one every 250 ms.
    assert!((4..=6).contains(&pings), "{pings} pings in 1.1 s: {:?}", peer.received());
    assert!(tb.keepalives_sent() >= 3);
    assert!(tb.fault().is_none());
    // The pings' round trips keep the clock mapping fed.
    let m = tb.clock_mapping().expect("mapping");
    assert!(m.samples >= 5, "{m:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn another_protocol_version_is_refused_naming_both() {
    let peer = BoxPeer::start_with(|b| b.protocol.store(3, Ordering::SeqCst));
    let Err(e) = TriggerBox::open(&peer.path, config(), MonotonicClock::new()).await else {
        panic!("protocol 3 must be refused");
    };
    assert_eq!(e.kind(), ErrorKind::Protocol, "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("protocol 3 (firmware 0.1.0)") && msg.contains("speaks protocol 2"),
        "{msg}"
    );
    assert!(msg.contains(&peer.path), "{msg}");

    let v1 = BoxPeer::start_with(|b| b.protocol.store(0, Ordering::SeqCst));
    let Err(e) = TriggerBox::open(&v1.path, config(), MonotonicClock::new()).await else {
        panic!("a protocol-1 box must be refused");
    };
    assert_eq!(e.kind(), ErrorKind::Protocol, "{e}");
    assert!(e.to_string().contains("does not know the V command"), "{e}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_busy_fire_is_sent_again_and_counted_not_a_fault() {
    let peer = BoxPeer::start();
    // Room for the retry: the peer's busy answer may take a few ms on a loaded machine.
    let cfg = TriggerBoxConfig { busy_retry_for: Duration::from_millis(200), ..config() };
    let mut tb = TriggerBox::open(&peer.path, cfg, MonotonicClock::new()).await.expect("open");
    peer.b.busy_fires.store(1, Ordering::SeqCst);
    tb.fire(11, CAMERA).expect("fire");
    let r = eventually(Duration::from_secs(2), || tb.poll_fired().expect("no fault"))
        .await
        .expect("the retried fire is acknowledged");
    assert_eq!(r.tick, 11);
    let fires: Vec<String> = peer.received().into_iter().filter(|l| l.starts_with("F ")).collect();
    assert_eq!(fires.len(), 2, "sent twice: {fires:?}");
    assert!(fires.iter().all(|l| l.ends_with(" 11 1")), "{fires:?}");
    let busy = tb.busy();
    assert_eq!((busy.answers, busy.retried, busy.given_up), (1, 1, 0));

    // Busy for longer than the retry window: given up, counted, still not a fault.
    let peer = BoxPeer::start_with(|b| b.busy_fires.store(100, Ordering::SeqCst));
    let quick = TriggerBoxConfig { busy_retry_for: Duration::ZERO, ..config() };
    let mut tb = TriggerBox::open(&peer.path, quick, MonotonicClock::new()).await.expect("open");
    tb.fire(12, CAMERA).expect("fire");
    eventually(Duration::from_secs(2), || (tb.busy().given_up == 1).then_some(()))
        .await
        .expect("given up");
    assert_eq!(tb.poll_fired().expect("no fault"), None);
    tb.health().expect("busy is never a fault");
}

/// `E 0 3`: the box dropped a command (its queue was full); the unanswered one is sent again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_command_the_box_dropped_is_sent_again() {
    let peer = BoxPeer::start();
    // Room for the retry: the drop is only known once the level's answer is back, which on a
    // loaded machine can take longer than the default retry window for a fire.
    let cfg = TriggerBoxConfig { busy_retry_for: Duration::from_millis(200), ..config() };
    let mut tb = TriggerBox::open(&peer.path, cfg, MonotonicClock::new()).await.expect("open");
    peer.b.drop_commands.store(1, Ordering::SeqCst);
    // The fire goes first and is dropped; the level after it is answered, which shows the fire
    // was the one dropped.
    tb.fire(5, CAMERA).expect("fire");
    tb.set_level(0.75).expect("level");
    let r = eventually(Duration::from_secs(2), || tb.poll_fired().expect("no fault"))
        .await
        .expect("fire acknowledged");
    assert_eq!(r.tick, 5);
    let fires: Vec<String> = peer.received().into_iter().filter(|l| l.starts_with("F ")).collect();
    assert_eq!(fires.len(), 2, "the dropped fire again: {:?}", peer.received());
    let busy = tb.busy();
    assert_eq!((busy.answers, busy.retried), (1, 1));
    tb.health().expect("not a fault");
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
