//! The DMX driver against a pty peer that plays the Enttec widget: framing, levels, refresh,
//! unplug and write timeout.

#![allow(clippy::unwrap_used)]

mod light_pty;

use std::time::Duration;

use hitl_drivers::light::{DmxConfig, DmxLight, DmxResolution};
use hitl_hal::{Error, ErrorKind, Lifecycle, Light};
use light_pty::{eventually, PtyPeer};

/// One label-6 message decoded from the byte stream: the DMX channel values (without start code).
#[derive(Debug)]
struct Frame {
    channels: Vec<u8>,
}

/// Split a byte stream into Enttec messages, checking every byte of the framing; a trailing
/// incomplete message is left in `rest`.
fn parse_frames(bytes: &[u8]) -> (Vec<Frame>, Vec<u8>) {
    let mut frames = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        assert_eq!(bytes[i], 0x7E, "message must start with 0x7E at byte {i}");
        if bytes.len() < i + 4 {
            break;
        }
        assert_eq!(bytes[i + 1], 6, "label must be 6 (Output Only Send DMX Packet)");
        let len = usize::from(bytes[i + 2]) | usize::from(bytes[i + 3]) << 8;
        assert!((25..=513).contains(&len), "data length {len} outside 25..=513");
        if bytes.len() < i + 4 + len + 1 {
            break;
        }
        let data = &bytes[i + 4..i + 4 + len];
        assert_eq!(data[0], 0x00, "DMX start code must be 0");
        assert_eq!(bytes[i + 4 + len], 0xE7, "message must end with 0xE7");
        frames.push(Frame { channels: data[1..].to_vec() });
        i += 4 + len + 1;
    }
    (frames, bytes[i..].to_vec())
}

/// Read frames from the peer until one satisfies `want` (all frames on the way must be valid).
fn wait_frame(peer: &mut PtyPeer, timeout: Duration, want: impl Fn(&Frame) -> bool) -> Frame {
    let deadline = std::time::Instant::now() + timeout;
    let mut pending = Vec::new();
    while std::time::Instant::now() < deadline {
        pending.extend(peer.read_some(1, Duration::from_millis(50)));
        let (frames, rest) = parse_frames(&pending);
        pending = rest;
        if let Some(f) = frames.into_iter().rev().find(|f| want(f)) {
            return f;
        }
    }
    panic!("no matching DMX frame within {timeout:?}");
}

fn fast() -> DmxConfig {
    DmxConfig { refresh: Duration::from_millis(20), ..DmxConfig::default() }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn levels_arrive_on_channel_one_in_valid_frames() {
    let mut peer = PtyPeer::new();
    let mut light = DmxLight::open(&peer.path, fast()).await.expect("open DMX light");
    // Starts dark: a full 512-channel universe of zeros.
    let f = wait_frame(&mut peer, Duration::from_secs(2), |_| true);
    assert_eq!(f.channels.len(), 512);
    assert!(f.channels.iter().all(|&c| c == 0));

    light.set_level(0.5).expect("set 0.5");
    let f = wait_frame(&mut peer, Duration::from_secs(2), |f| f.channels[0] != 0);
    assert_eq!(f.channels[0], 128);
    assert!(f.channels[1..].iter().all(|&c| c == 0), "only channel 1 carries the level");

    light.set_level(1.0).expect("set 1.0");
    let f = wait_frame(&mut peer, Duration::from_secs(2), |f| f.channels[0] == 255);
    assert_eq!(f.channels[0], 255);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_universe_is_refreshed_without_changes() {
    let mut peer = PtyPeer::new();
    let mut light = DmxLight::open(&peer.path, fast()).await.expect("open DMX light");
    light.set_level(0.2).expect("set");
    wait_frame(&mut peer, Duration::from_secs(2), |f| f.channels[0] == 51);
    // Nothing changes for 300 ms; at a 20 ms refresh about 15 more frames come (at least 3 even
    // on a loaded machine).
    let bytes = peer.read_some(usize::MAX, Duration::from_millis(300));
    let (frames, _) = parse_frames(&bytes);
    assert!(frames.len() >= 3, "only {} refresh frames in 300 ms", frames.len());
    assert!(frames.iter().all(|f| f.channels[0] == 51));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixteen_bit_level_at_a_start_address() {
    let mut peer = PtyPeer::new();
    let cfg = DmxConfig {
        start_address: 5,
        resolution: DmxResolution::Bits16,
        universe_channels: 24,
        ..fast()
    };
    let mut light = DmxLight::open(&peer.path, cfg).await.expect("open DMX light");
    light.set_level(0.25).expect("set");
    // 0.25 * 65535 = 16383.75 -> 16384 = 0x4000 on channels 5 (coarse) and 6 (fine).
    let f = wait_frame(&mut peer, Duration::from_secs(2), |f| f.channels[4] != 0);
    assert_eq!(f.channels.len(), 24);
    assert_eq!(&f.channels[4..6], &[0x40, 0x00]);
    assert!(f.channels[..4].iter().chain(&f.channels[6..]).all(|&c| c == 0));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_levels_are_refused_without_tripping() {
    let peer = PtyPeer::new();
    let mut light = DmxLight::open(&peer.path, fast()).await.expect("open DMX light");
    for bad in [f32::NAN, -0.1, 1.5, f32::INFINITY] {
        let e = light.set_level(bad).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidRequest, "level {bad}");
    }
    light.set_level(0.3).expect("a good level still works");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unplug_is_reported_as_disconnected() {
    let peer = PtyPeer::new();
    let mut light = DmxLight::open(&peer.path, fast()).await.expect("open DMX light");
    light.set_level(0.5).expect("set");
    drop(peer);
    let e = eventually(Duration::from_secs(3), || light.set_level(0.5).err())
        .await
        .expect("unplug must surface as an error");
    assert_eq!(e.kind(), ErrorKind::Disconnected, "{e}");
    assert!(e.to_string().contains("unplugged"), "{e}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_peer_that_stops_reading_causes_a_write_timeout() {
    let peer = PtyPeer::new();
    let cfg = DmxConfig {
        refresh: Duration::from_millis(1),
        poll: Duration::from_millis(1),
        min_interval: Duration::from_millis(1),
        write_timeout: Duration::from_millis(50),
        ..DmxConfig::default()
    };
    let mut light = DmxLight::open(&peer.path, cfg).await.expect("open DMX light");
    // The peer never reads: the pty's buffer fills and a write stalls past its timeout.
    let e = eventually(Duration::from_secs(20), || light.set_level(0.5).err())
        .await
        .expect("a stalled write must surface as an error");
    assert_eq!(e.kind(), ErrorKind::Timeout, "{e}");
    drop(peer);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_missing_port_is_not_found_and_named() {
    let Err(e) = DmxLight::open("/dev/hitl-no-such-port", fast()).await else {
        panic!("opening a missing port must fail");
    };
    assert_eq!(e.kind(), ErrorKind::NotFound, "{e}");
    assert!(e.to_string().contains("/dev/hitl-no-such-port"), "{e}");
}

/// The bug behind issue 12: a light opened in a runtime that is then dropped loses its refresh
/// task. That must never be silent: the next health check (every tick) reports it.
#[test]
fn a_light_whose_runtime_is_gone_reports_it_at_the_next_health_check() {
    let mut peer = PtyPeer::new();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let mut light = rt.block_on(DmxLight::open(&peer.path, fast())).expect("open DMX light");
    light.health().expect("healthy while its runtime runs");
    drop(rt);
    let e = light.health().unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Disconnected, "{e}");
    assert!(e.to_string().contains("task has ended"), "{e}");
    assert!(light.set_level(0.5).is_err(), "the tick's next level is refused too");
    drop(peer.read_some(usize::MAX, Duration::from_millis(20)));
}

/// `stop` writes the current level once more, ends the task and lets go of the port: the port
/// can be opened again at once (serial ports are opened exclusively).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stop_writes_the_last_level_and_releases_the_port() {
    let mut peer = PtyPeer::new();
    let mut light = DmxLight::open(&peer.path, fast()).await.expect("open DMX light");
    light.set_level(0.6).expect("set");
    wait_frame(&mut peer, Duration::from_secs(2), |f| f.channels[0] == 153);
    assert!(
        DmxLight::open(&peer.path, fast()).await.is_err(),
        "a port in use cannot be opened twice"
    );
    let mut stopped = tokio::task::spawn_blocking(move || {
        let r = light.stop();
        (r, light)
    })
    .await
    .unwrap();
    stopped.0.expect("stop finishes in time");
    let last = wait_frame(&mut peer, Duration::from_secs(2), |_| true);
    assert_eq!(last.channels[0], 153, "the last frame carries the level");
    stopped.1.health().expect("a stopped light is not a faulty one");
    let again = DmxLight::open(&peer.path, fast()).await;
    assert!(again.is_ok(), "the port is free after stop: {:?}", again.err());
}
