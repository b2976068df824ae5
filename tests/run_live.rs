//! `hitl run --live`: a Foxglove WebSocket viewer (subprotocol `foxglove.sdk.v1`) on loopback sees
//! `/arm/state`, `/tf` and `/camera/color` advertised while a stub run goes on, subscribes, and
//! receives them: joint positions that are finite and within the arm's range, colour images of
//! the camera's size; the operator then stops the run (Ctrl-C) and its summary counts the viewer.
//! A non-loopback address without `--allow-remote`, a malformed one and a port
//! in use are refused before anything moves.

use std::collections::BTreeMap;
use std::fs::File;
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::http::HeaderValue;
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

mod common;
use common::{hitl, plan_flyaround, SIM_CAPTURE_RUN};

/// A port nothing listens on right now.
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    l.local_addr().expect("addr").port()
}

/// The shared 20 s fly-around at 10 m with a capture every 25 waypoints.
fn plan(out: &Path) {
    plan_flyaround(out, "10", "25");
}

/// What the run printed so far (stdout, then stderr).
fn printed(dir: &Path) -> String {
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    format!("{}{}", read("stdout"), read("stderr"))
}

/// Connect as Foxglove does, retrying while the run sets up (up to 60 s).
fn connect(port: u16, run: &mut Child, dir: &Path) -> WebSocket<MaybeTlsStream<TcpStream>> {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let mut req = format!("ws://127.0.0.1:{port}/").into_client_request().expect("request");
        req.headers_mut()
            .insert("sec-websocket-protocol", HeaderValue::from_static("foxglove.sdk.v1"));
        match tungstenite::client::connect(req) {
            Ok((ws, resp)) => {
                let proto = resp.headers().get("sec-websocket-protocol");
                assert_eq!(proto.and_then(|v| v.to_str().ok()), Some("foxglove.sdk.v1"));
                if let MaybeTlsStream::Plain(s) = ws.get_ref() {
                    s.set_read_timeout(Some(Duration::from_millis(500))).expect("timeout");
                }
                return ws;
            }
            Err(e) => {
                let out = printed(dir);
                assert!(run.try_wait().expect("wait").is_none(), "the run ended first: {e}\n{out}");
                assert!(Instant::now() < deadline, "no live view on port {port}: {e}\n{out}");
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

#[test]
fn a_viewer_sees_state_tf_and_camera_advertised_and_receives_them_while_the_run_goes_on() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (traj, mcap) = (dir.path().join("fly.npz"), dir.path().join("run.mcap"));
    plan(&traj);
    let port = free_port();
    let live = format!("127.0.0.1:{port}");
    let (out_path, err_path) = (dir.path().join("stdout"), dir.path().join("stderr"));
    let mut run = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args([
            "run",
            traj.to_str().expect("utf-8"),
            "--record",
            mcap.to_str().expect("utf-8"),
            "--live",
            &live,
        ])
        .args(SIM_CAPTURE_RUN)
        .stdin(Stdio::null())
        .stdout(File::create(&out_path).expect("stdout file"))
        .stderr(File::create(&err_path).expect("stderr file"))
        .spawn()
        .expect("start hitl run");

    let mut ws = connect(port, &mut run, dir.path());
    let wanted = ["/arm/state", "/tf", "/camera/color"];
    // channel id -> (topic, encoding, schema name), as advertised.
    let mut advertised: BTreeMap<u64, (String, String, String)> = BTreeMap::new();
    let mut subscribed = false;
    let mut received: BTreeMap<&str, u64> = BTreeMap::new();
    let mut images = Vec::new();
    let mut max_abs_q = 0.0f64;
    let deadline = Instant::now() + Duration::from_secs(60);
    let done = |r: &BTreeMap<&str, u64>| {
        r.get("/arm/state").is_some_and(|n| *n >= 50) && wanted.iter().all(|t| r.contains_key(t))
    };
    while !done(&received) {
        assert!(
            Instant::now() < deadline,
            "advertised {advertised:?}, received {received:?}\n{}",
            printed(dir.path())
        );
        let msg = match ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue
            }
            Err(e) => panic!("viewer: {e} (received {received:?})\n{}", printed(dir.path())),
        };
        match msg {
            Message::Text(text) => {
                let v: serde_json::Value = serde_json::from_str(&text).expect("json");
                if v["op"] != "advertise" {
                    continue;
                }
                for c in v["channels"].as_array().expect("channels") {
                    let s = |k: &str| c[k].as_str().unwrap_or_default().to_string();
                    let id = c["id"].as_u64().expect("channel id");
                    advertised.insert(id, (s("topic"), s("encoding"), s("schemaName")));
                }
                let ids: Vec<(u64, &str)> = wanted
                    .iter()
                    .filter_map(|t| {
                        advertised.iter().find(|(_, c)| c.0 == *t).map(|(id, _)| (*id, *t))
                    })
                    .collect();
                if !subscribed && ids.len() == wanted.len() {
                    let subs: Vec<_> = ids
                        .iter()
                        .enumerate()
                        .map(|(i, (id, _))| serde_json::json!({"id": i + 1, "channelId": id}))
                        .collect();
                    let sub = serde_json::json!({"op": "subscribe", "subscriptions": subs});
                    ws.send(Message::Text(sub.to_string().into())).expect("subscribe");
                    subscribed = true;
                }
            }
            Message::Binary(b) => {
                // Message data: opcode 1, subscription id (u32 LE), log time (u64 LE), payload.
                assert!(
                    b.len() >= 13 && b[0] == 1,
                    "not message data: {:?}",
                    &b[..b.len().min(13)]
                );
                let sub = u32::from_le_bytes(b[1..5].try_into().expect("4 bytes")) as usize;
                let topic = wanted[sub - 1];
                let payload = &b[13..];
                *received.entry(topic).or_default() += 1;
                match topic {
                    "/arm/state" => {
                        let v: serde_json::Value = serde_json::from_slice(payload).expect("json");
                        let q = v["q"].as_array().expect("q");
                        assert_eq!(q.len(), 7, "{v}");
                        for x in q {
                            let x = x.as_f64().expect("number");
                            assert!(x.is_finite(), "{v}");
                            max_abs_q = max_abs_q.max(x.abs());
                        }
                    }
                    "/camera/color" => {
                        images.push(hitl_record::reader::decode_image(payload).expect("RawImage"))
                    }
                    _ => assert!(!payload.is_empty()),
                }
            }
            _ => {}
        }
    }
    // All of it arrived while the run was still going; the operator stops it now (Ctrl-C).
    assert!(run.try_wait().expect("wait").is_none(), "the run had ended");
    let ctrl_c = Command::new("kill").args(["-INT", &run.id().to_string()]).status();
    assert!(ctrl_c.expect("kill").success(), "Ctrl-C");

    for t in wanted {
        let (_, enc, schema) = advertised.values().find(|c| c.0 == t).expect("advertised");
        let expect = match t {
            "/arm/state" => ("json", "hitl.ArmState"),
            "/tf" => ("protobuf", "foxglove.FrameTransforms"),
            _ => ("protobuf", "foxglove.RawImage"),
        };
        assert_eq!((enc.as_str(), schema.as_str()), expect, "{t}");
    }
    // Within the xArm7's widest joint range (+-2 pi) and not all zero.
    assert!(max_abs_q > 0.01 && max_abs_q <= 2.0 * std::f64::consts::PI + 1e-6, "{max_abs_q}");
    // The 320x256 camera is not shrunk (at most 320 px wide live).
    for img in &images {
        assert_eq!((img.width, img.height, img.encoding.as_str()), (320, 256, "rgb8"));
        assert_eq!(img.data.len(), 320 * 256 * 3);
    }
    drop(ws);

    let status = run.wait().expect("wait for the run");
    let out = std::fs::read_to_string(&out_path).unwrap_or_default();
    let err = std::fs::read_to_string(&err_path).unwrap_or_default();
    // An operator stop after a controlled stop (the live view changes nothing about the run).
    assert_eq!(status.code(), Some(130), "{out}{err}");
    assert!(out.contains("stopped by operator-stop"), "{out}");
    let line = out.lines().find(|l| l.starts_with("live view ")).unwrap_or_else(|| panic!("{out}"));
    assert!(line.contains(&format!("ws://{live}: 1 viewer(s)")), "{line}");
    let sent: u64 = line
        .split(", ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    let seen: u64 = received.values().sum();
    assert!(sent >= seen, "{line}: the viewer got {seen}");
    assert!(line.contains("live dropped "), "{line}");
}

#[test]
fn live_off_loopback_without_opt_in_malformed_or_on_a_port_in_use_is_refused_before_motion() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (traj, mcap) = (dir.path().join("fly.npz"), dir.path().join("run.mcap"));
    plan(&traj);
    let (t, m) = (traj.to_str().expect("utf-8"), mcap.to_str().expect("utf-8"));
    let text = |o: &std::process::Output| {
        format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
    };

    let remote = hitl(
        &[&["run", t, "--record", m, "--live", "0.0.0.0:8765"][..], &SIM_CAPTURE_RUN].concat(),
    );
    let o = text(&remote);
    assert_eq!(remote.status.code(), Some(2), "{o}");
    assert!(o.contains("refusing to serve the live view on 0.0.0.0:8765"), "{o}");
    assert!(o.contains("--allow-remote") && o.contains("nothing moved"), "{o}");
    assert!(!o.contains("completed") && !mcap.exists(), "{o}");

    // A trajectory after a bare --live is taken as its address: refused, with the way out.
    let swapped = hitl(&["run", "--live", t, "--plain"]);
    let o = text(&swapped);
    assert_eq!(swapped.status.code(), Some(2), "{o}");
    assert!(o.contains("is not an address") && o.contains("--live=ADDR"), "{o}");

    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = taken.local_addr().expect("addr").to_string();
    let busy = hitl(&[&["run", t, "--record", m, "--live", &addr][..], &SIM_CAPTURE_RUN].concat());
    let o = text(&busy);
    assert_eq!(busy.status.code(), Some(5), "{o}");
    assert!(o.contains(&format!("live view: cannot listen on {addr}")), "{o}");
    assert!(!o.contains("completed") && !mcap.exists(), "{o}");
}
