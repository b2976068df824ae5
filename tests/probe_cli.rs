//! `hitl probe` end to end: against `hitl stub` on loopback (the arm's identity and table), and
//! the devices that do not answer (exit 5 naming them) or are mis-named (exit 2).

mod common;

use common::hitl;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

fn text(out: &std::process::Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// `hitl stub` on free loopback ports; returns the child and its command port once it serves.
fn start_stub() -> (Child, u16) {
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
    (child, cmd)
}

#[test]
fn probe_prints_the_stub_arms_identity_and_table_and_moves_nothing() {
    let (mut stub, port) = start_stub();
    let out = hitl(&["probe", "--arm", &format!("127.0.0.1:{port}")]);
    let _ = stub.kill();
    let _ = stub.wait();
    let all = text(&out);
    assert_eq!(out.status.code(), Some(0), "{all}");
    assert!(all.contains("serial XS1305"), "{all}");
    assert!(all.contains("joint-limit table xarm7-current"), "{all}");
    assert!(all.contains("J4 -0.1047..3.9270"), "{all}");
    assert!(all.contains("error code 0, warning code 0"), "{all}");
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
