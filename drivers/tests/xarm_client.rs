//! The xArm client against scripted peers on loopback: a reply with another protocol id than its
//! request's is an error; motion_enable waits longer than the ordinary reply timeout (the box
//! answers it only once the motors are powered); stop() returns without its reply and discards
//! it when it comes; a report stream whose frame size changes, or whose state is out of range,
//! is a fault of the link.

use hitl_drivers::xarm::codec::{decode_request, encode_reply, frame_len, Accept, CodecError};
use hitl_drivers::xarm::registers as reg;
use hitl_drivers::xarm::report::{encode_report, BoxIdentity, ReportData, ReportKind};
use hitl_drivers::xarm::{ClientConfig, ReportConfig, ReportReader, XarmClient, XarmError};
use hitl_hal::{Arm, ArmReports};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Read one request frame; `None` when the client closed.
fn read_request(s: &mut TcpStream) -> Option<(u16, u8, Vec<u8>)> {
    let mut buf = vec![0u8; 6];
    s.read_exact(&mut buf).ok()?;
    let total = frame_len(&buf, Accept::Any).ok()??;
    buf.resize(total, 0);
    s.read_exact(&mut buf[6..]).ok()?;
    let r = decode_request(&buf).ok()?;
    Some((r.transaction, r.register, r.params.to_vec()))
}

fn reply(s: &mut TcpStream, t: u16, protocol: u16, register: u8) {
    let mut out = [0u8; 64];
    let n = encode_reply(&mut out, t, protocol, register, 0, &[]).expect("fits");
    s.write_all(&out[..n]).expect("written");
}

/// A peer that answers each request through `answer` (on its own thread).
fn peer(
    answer: impl Fn(&mut TcpStream, u16, u8) + Send + 'static,
) -> (std::net::SocketAddr, JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = l.local_addr().expect("addr");
    let h = std::thread::spawn(move || {
        let (mut s, _) = l.accept().expect("accept");
        while let Some((t, register, _)) = read_request(&mut s) {
            answer(&mut s, t, register);
        }
    });
    (addr, h)
}

#[test]
fn a_reply_with_another_protocol_id_is_refused() {
    let (addr, h) = peer(|s, t, register| reply(s, t, 3, register));
    let mut arm = XarmClient::connect(addr, ClientConfig::default()).expect("connects");
    let err = arm.state().expect_err("protocol 3 answers a protocol 2 request");
    assert!(
        matches!(err, XarmError::Codec(CodecError::ProtocolMismatch { got: 3, want: 2 })),
        "{err}"
    );
    drop(arm);
    h.join().expect("peer");
}

#[test]
fn motion_enable_waits_beyond_the_reply_timeout() {
    let (addr, h) = peer(|s, t, register| {
        if register == reg::MOTION_EN {
            std::thread::sleep(Duration::from_millis(1500));
        }
        reply(s, t, 2, register);
    });
    let config = ClientConfig { reply_timeout: Duration::from_millis(500), ..Default::default() };
    let mut arm = XarmClient::connect(addr, config).expect("connects");
    let t = Instant::now();
    arm.motion_enable(true).expect("answered after 1.5 s: within motion_enable's 5 s");
    assert!(t.elapsed() >= Duration::from_millis(1400));
    drop(arm);
    h.join().expect("peer");
}

#[test]
fn stop_returns_without_its_reply_and_discards_it_later() {
    // The peer answers set_state only after 300 ms; everything else at once.
    let (addr, h) = peer(|s, t, register| {
        if register == reg::SET_STATE {
            std::thread::sleep(Duration::from_millis(300));
        }
        reply(s, t, 2, register);
    });
    let mut arm = XarmClient::connect(addr, ClientConfig::default()).expect("connects");
    let t = Instant::now();
    arm.stop().expect("written");
    // Well under the reply's 300 ms (room for a loaded machine): the stop did not wait for it.
    assert!(t.elapsed() < Duration::from_millis(200), "stop waited {:?}", t.elapsed());
    assert_eq!(arm.outstanding(), 1);
    // A request after it gets its own reply; the stop's is taken on the way and discarded.
    arm.clean_warn().expect("clean_warn answered");
    assert_eq!(arm.outstanding(), 0);
    drop(arm);
    h.join().expect("peer");
}

fn report_peer(frames: Vec<Vec<u8>>) -> (std::net::SocketAddr, JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = l.local_addr().expect("addr");
    let h = std::thread::spawn(move || {
        let (mut s, _) = l.accept().expect("accept");
        for f in frames {
            if s.write_all(&f).is_err() {
                return;
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    });
    (addr, h)
}

fn frame(kind: ReportKind, state: u8) -> Vec<u8> {
    let id =
        BoxIdentity { robot_type: 7, axis: 7, version: "v2.5.0", joint_limits: [(-1.0, 1.0); 7] };
    let r = ReportData { state, mode: 1, ..ReportData::default() };
    let mut buf = [0u8; 1024];
    let n = encode_report(&mut buf, kind, &r, &id).expect("fits");
    buf[..n].to_vec()
}

fn reader(addr: std::net::SocketAddr, kind: ReportKind) -> ReportReader {
    let config =
        ReportConfig { kind, port: Some(addr.port()), codes_port: None, ..Default::default() };
    ReportReader::connect(addr.ip(), config).expect("connects")
}

#[test]
fn report_streams_that_change_size_or_say_nonsense_are_faults() {
    // A real report (135 bytes), then a normal one (145 bytes) on the same stream.
    let (addr, h) = report_peer(vec![frame(ReportKind::Real, 2), frame(ReportKind::Normal, 2)]);
    let mut r = reader(addr, ReportKind::Real);
    assert_eq!(r.next_report().expect("first frame").state, 2);
    let err = r.next_report().expect_err("size changed");
    assert!(
        matches!(err, XarmError::Codec(CodecError::ReportSizeChanged { first: 135, got: 145 })),
        "{err}"
    );
    h.join().expect("peer");

    // State 12 is nothing a box sends.
    let mut bad = frame(ReportKind::Real, 2);
    bad[4] = 0x1C;
    let (addr, h) = report_peer(vec![frame(ReportKind::Real, 4), bad]);
    let mut r = reader(addr, ReportKind::Real);
    assert_eq!(r.next_report().expect("first frame").state, 4);
    let err = r.next_report().expect_err("state out of range");
    assert!(
        matches!(err, XarmError::Codec(CodecError::ReportField { field: "state", .. })),
        "{err}"
    );
    h.join().expect("peer");
}
