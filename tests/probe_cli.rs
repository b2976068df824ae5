//! `hitl probe` end to end: against `hitl stub` on loopback (the arm's identity and table), and
//! the devices that do not answer (exit 5 naming them) or are mis-named (exit 2).

mod common;
#[path = "../drivers/tests/light_pty/mod.rs"]
mod light_pty;

use common::hitl;
use light_pty::PtyPeer;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn text(out: &std::process::Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// `hitl stub` on free loopback ports; returns the child, its command port and its real report
/// port once it serves.
fn start_stub() -> (Child, u16, u16) {
    let free = || {
        std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("free port")
    };
    let (cmd, report) = (free(), free().max(3));
    let mut child = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["stub", "--cmd-port", &cmd.to_string(), "--report-port", &report.to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start hitl stub");
    let stderr = child.stderr.take().expect("stderr");
    let mut lines = BufReader::new(stderr).lines();
    loop {
        match lines.next() {
            Some(Ok(l)) if l.contains("serving until Ctrl-C") => break,
            Some(Ok(_)) => {}
            _ => {
                let _ = child.kill();
                panic!("hitl stub ended before serving");
            }
        }
    }
    // Keep draining its stderr so the stub never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    (child, cmd, report)
}

#[test]
fn probe_prints_the_stub_arms_identity_and_table_and_moves_nothing() {
    let (mut stub, port, report) = start_stub();
    let out = hitl(&[
        "probe",
        "--arm",
        &format!("127.0.0.1:{port}"),
        "--report-port",
        &report.to_string(),
    ]);
    let _ = stub.kill();
    let _ = stub.wait();
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("serial XS1305"), "{all}");
    assert!(all.contains("joint-limit table xarm7-current"), "{all}");
    assert!(all.contains("J4 -0.1047..3.9270"), "{all}");
    assert!(all.contains("error code 0, warning code 0"), "{all}");
    // The report ports a run also needs: the stub's arm at its power-up pose, in position mode.
    assert!(
        all.contains(&format!(
            "report ports {report} (real, joints, state, mode) and {} (normal, codes): answered",
            report - 2
        )),
        "{all}"
    );
    assert!(all.contains("mode 0 (position), error 0, warning 0"), "{all}");
    assert!(all.contains("joints: J1 0.0000, J2 -0.5000, J3 0.0000, J4 0.9000"), "{all}");
    assert!(all.contains("every named device answered"), "{all}");
}

#[test]
fn an_arm_that_does_not_answer_is_named_with_exit_5() {
    // Port 1 on loopback: nothing listens, the connection is refused at once.
    let out = hitl(&["probe", "--arm", "127.0.0.1:1"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("probe: arm did not answer"), "{all}");
}

#[test]
fn a_missing_serial_light_is_named_with_exit_5() {
    let out = hitl(&["probe", "--light", "trigger:/dev/hitl-no-such-port"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("probe: light did not answer"), "{all}");
    assert!(all.contains("/dev/hitl-no-such-port"), "{all}");
}

#[test]
fn a_required_camera_that_is_absent_is_named_with_exit_5() {
    let out = hitl(&["probe", "--camera"]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("probe: camera did not answer"), "{all}");
}

#[test]
fn a_misspelt_light_is_bad_input() {
    let out = hitl(&["probe", "--light", "dmxx:/dev/ttyUSB0"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("unknown light kind"), "{}", text(&out));
}

/// A trigger box on a pty (protocol 2): answers every command (`V` with its versions) and
/// reports its inputs every 20 ms with the door open, until `done`.
fn trigger_box_peer(mut peer: PtyPeer, done: Arc<AtomicBool>) {
    let start = Instant::now();
    let mut line = Vec::new();
    let mut last = Instant::now() - Duration::from_secs(1);
    while !done.load(Ordering::Acquire) {
        for b in peer.read_some(1, Duration::from_millis(5)) {
            if b != b'\n' {
                line.push(b);
                continue;
            }
            let text = String::from_utf8(std::mem::take(&mut line)).expect("ASCII");
            if text.is_empty() {
                continue; // ignored, not answered (protocol 2)
            }
            let seq = text.split(' ').nth(1).unwrap_or("0").to_string();
            let us = start.elapsed().as_micros();
            if text.starts_with("V ") {
                peer.write(format!("V {seq} {us} 2 0.1.0\n").as_bytes());
            } else {
                peer.write(format!("A {seq} {us}\n").as_bytes());
            }
        }
        if last.elapsed() >= Duration::from_millis(20) {
            peer.write(format!("I {} 0 1\n", start.elapsed().as_micros()).as_bytes());
            last = Instant::now();
        }
    }
}

#[test]
fn probe_pings_the_trigger_box_and_prints_its_inputs() {
    let peer = PtyPeer::new();
    let path = peer.path.clone();
    let done = Arc::new(AtomicBool::new(false));
    let stop = Arc::clone(&done);
    let thread = std::thread::spawn(move || trigger_box_peer(peer, stop));
    let out = hitl(&["probe", "--light", &format!("trigger:{path}")]);
    done.store(true, Ordering::Release);
    thread.join().expect("peer");
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("firmware 0.1.0, protocol 2; e-stop released, door OPEN"), "{all}");
}

#[test]
fn probe_asks_the_dmx_widget_for_its_parameters() {
    let mut peer = PtyPeer::new();
    let path = peer.path.clone();
    let thread = std::thread::spawn(move || {
        // The request: label 3, two bytes of user-configuration length (0), end.
        let got = peer.read_some(7, Duration::from_secs(5));
        peer.write(&[0x7E, 3, 5, 0, 0x44, 0x01, 9, 1, 40, 0xE7]);
        std::thread::sleep(Duration::from_millis(300));
        got
    });
    let out = hitl(&["probe", "--light", &format!("dmx:{path}")]);
    let got = thread.join().expect("peer");
    let all = text(&out);
    assert_eq!(got, vec![0x7E, 3, 2, 0, 0, 0, 0xE7], "parameters request");
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("firmware 1.68"), "{all}");
    assert!(all.contains("break 96 us, mark-after-break 11 us, 40 packets/s"), "{all}");
}

#[test]
fn a_serial_port_that_is_no_dmx_widget_is_named_with_exit_5() {
    let peer = PtyPeer::new(); // answers nothing
    let out = hitl(&["probe", "--light", &format!("dmx:{}", peer.path)]);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(5), "{all}");
    assert!(all.contains("no parameters reply within 500 ms"), "{all}");
}
