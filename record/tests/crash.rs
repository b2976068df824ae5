//! Crash safety: a recorder killed with SIGKILL leaves a file readable up to its last flushed
//! chunk (at most about a second lost); a recorder that hits a file-size limit (disk full)
//! raises its health flag, stops writing, and leaves what it wrote readable.
//!
//! The recording child is this test binary re-run with `HITL_RECORD_CHILD` set: it runs the
//! ignored test `child_recorder`.

mod common;

use common::*;
use hitl_record::reader::read_recording;
use hitl_record::*;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHILD_ENV: &str = "HITL_RECORD_CHILD";
const PATH_ENV: &str = "HITL_RECORD_CHILD_PATH";

/// Pseudo-random bytes (incompressible enough to grow the file quickly).
fn noise(n: usize, seed: u64) -> Vec<u8> {
    let mut x = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
    (0..n)
        .map(|_| {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (x >> 33) as u8
        })
        .collect()
}

/// A line to the parent, flushed at once (the harness's stdout may be buffered).
fn say(line: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// The recording child: 250 Hz telemetry stamped with nanoseconds since its start, a 64x48
/// frame every 10 ticks. Prints `started`, then `failed <reason>` if the recorder fails.
#[test]
#[ignore = "run by the crash tests as a child process"]
fn child_recorder() {
    let Ok(mode) = std::env::var(CHILD_ENV) else {
        return;
    };
    let path = std::env::var(PATH_ENV).expect("path");
    let (handle, tel) = Recorder::spawn(&path, &meta()).expect("spawn");
    let health = handle.health();
    let start = Instant::now();
    say("started");
    let (w, h) = (64u32, 48u32);
    let mut k = 0u64;
    loop {
        let t = start.elapsed().as_nanos() as u64 + 1;
        tel.push_setpoint(&SetpointMsg {
            tick: k,
            t_ns: t,
            phase: Phase::Playback,
            q: [0.0; 7],
            qd: [0.0; 7],
        });
        tel.push_timing(&TimingMsg {
            tick: k,
            t_ns: t,
            wake_late_ns: 0,
            tick_ns: 1000,
            overrun: false,
        });
        if k.is_multiple_of(10) {
            let mut f = frame(k, t, true);
            f.intrinsics.width = w;
            f.intrinsics.height = h;
            f.color =
                Some(Plane { width: w, height: h, data: noise((w * h * 3) as usize, k).into() });
            f.depth = Some(DepthImage::Millimetres(Plane {
                width: w,
                height: h,
                data: noise((w * h * 2) as usize, k + 7)
                    .chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect::<Vec<_>>()
                    .into(),
            }));
            f.mask = None;
            tel.push_frame(f);
        }
        // What the control loop does every tick.
        if health.is_failed() {
            say(&format!("failed {}", health.failure().unwrap_or_default()));
            break;
        }
        if start.elapsed() > Duration::from_secs(30) {
            say(&format!("stopped after 30 s ({mode})"));
            break;
        }
        k += 1;
        std::thread::sleep(Duration::from_millis(4));
    }
    match handle.finish() {
        Err(RecordError::Failed { reason, summary }) => {
            say(&format!("finish-failed {reason} written {}", summary.written[topics::SETPOINT]));
        }
        other => say(&format!("finish {other:?}")),
    }
}

fn spawn_child(mode: &str, path: &Path, wrap_fsize_kib: Option<u64>) -> Child {
    let exe = std::env::current_exe().expect("current exe");
    let args = ["child_recorder", "--exact", "--ignored", "--nocapture", "--test-threads=1"];
    let mut cmd = match wrap_fsize_kib {
        // Ignore SIGXFSZ (so the write fails with EFBIG instead of killing), cap file size.
        Some(kib) => {
            let mut c = Command::new("bash");
            c.arg("-c")
                .arg(format!("trap '' XFSZ; ulimit -f {kib}; exec \"$0\" \"$@\""))
                .arg(exe)
                .args(args);
            c
        }
        None => {
            let mut c = Command::new(exe);
            c.args(args);
            c
        }
    };
    cmd.env(CHILD_ENV, mode)
        .env(PATH_ENV, path)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn child")
}

/// Read the child's stdout until a line starting with `want`; the instant it was seen, the
/// lines so far, and the rest of the stream (kept open so the child can go on printing).
fn wait_for_line(
    child: &mut Child,
    want: &str,
) -> (Instant, Vec<String>, std::io::Lines<BufReader<std::process::ChildStdout>>) {
    let out = child.stdout.take().expect("stdout");
    let mut lines = Vec::new();
    let mut it = BufReader::new(out).lines();
    for line in it.by_ref() {
        let line = line.expect("read child");
        let hit = line.contains(want);
        lines.push(line);
        if hit {
            return (Instant::now(), lines, it);
        }
    }
    panic!("child ended without printing {want:?}: {lines:?}");
}

#[test]
fn sigkill_loses_at_most_the_last_second() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("killed.mcap");
    let mut child = spawn_child("kill", &path, None);
    let (started, _, _rest) = wait_for_line(&mut child, "started");
    std::thread::sleep(Duration::from_millis(2500));
    child.kill().expect("SIGKILL");
    // Time since the child's clock started is at least this.
    let alive_s = started.elapsed().as_secs_f64();
    let _ = child.wait();
    let v = python_read(&path, &[0]);
    assert_eq!(v["complete"], false, "a killed file has no footer");
    assert_eq!(v["metadata"]["run"]["trajectory_sha256"], "ab".repeat(32));
    let last_s = v["last_log_time"]["/arm/setpoint"].as_f64().unwrap_or(0.0) * 1e-9;
    assert!(
        last_s >= alive_s - 1.0,
        "last setpoint at {last_s:.3} s, killed after {alive_s:.3} s: more than 1 s lost ({v})"
    );
    // 250 Hz nominal; sleep granularity makes it a little slower, and a loaded machine can
    // starve the child (the bound is about the recorder keeping what was pushed, not the rate).
    let n = count(&v, "/arm/setpoint");
    assert!(n as f64 >= (alive_s - 1.0) * 50.0, "only {n} setpoints in {alive_s:.2} s");
    assert!(count(&v, "/camera/depth") >= 10, "{v}");
    assert!(v["depth"]["width"] == 64, "{v}");

    // Our reader reads the same file and says it was cut short.
    let rec = read_recording(&path).expect("read killed file");
    let end = rec.end.clone().expect("end");
    assert!(!end.complete);
    assert!(rec.setpoints.len() as u64 >= n);
}

#[test]
fn file_size_limit_fails_the_recorder_and_keeps_the_file_readable() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("full.mcap");
    let limit_kib = 512;
    let mut child = spawn_child("fsize", &path, Some(limit_kib));
    let (_, lines, more) = wait_for_line(&mut child, "failed");
    let rest: Vec<String> = more.map_while(Result::ok).collect();
    let rest = rest.join("\n");
    let status = child.wait().expect("wait");
    let failed = lines.last().cloned().unwrap_or_default();
    assert!(failed.contains("File too large"), "{failed}");
    assert!(rest.contains("finish-failed"), "{rest}");
    assert!(status.success(), "child exit {status:?}: {rest}");

    let size = std::fs::metadata(&path).expect("file").len();
    assert!(size <= limit_kib * 1024, "{size} bytes");
    assert!(size > limit_kib * 1024 / 2, "{size} bytes: the limit was not what failed");
    let v = python_read(&path, &[0]);
    assert_eq!(v["complete"], false);
    assert!(count(&v, "/arm/setpoint") > 20, "{v}");
    assert!(count(&v, "/camera/depth") >= 2, "{v}");
    assert_eq!(v["metadata"]["run"]["scale"], "0.01");
    let rec = read_recording(&path).expect("read full file");
    assert!(!rec.setpoints.is_empty());
}
