//! `socket:PATH`: pose estimation by an external process (e.g. FoundationPose on a GPU box) over
//! a local Unix domain socket, protocol `hitl-pose` version 1.
//!
//! This module owns the client side: connecting and the `hello` handshake (which hands the peer
//! the target mesh), one request/reply exchange per frame, `reset`, timeouts, reconnecting after a
//! failure, and turning every way the peer can misbehave into a [`PerceptionError::External`]
//! that names the socket and the problem. [`wire`] holds the byte format. The protocol is
//! specified in docs/perception.md ("External estimator over a socket"); `scripts/pose_peer.py`
//! is a reference peer.
//!
//! Blocking I/O with deadlines: [`PoseEstimator::estimate`] runs on tokio's blocking pool.
//! [`PoseEstimator::reset`] is called from the worker's async task, so it does no I/O: it marks a
//! reset that goes out just before the next frame (several resets in a row send one), and a
//! failure of it is reported by that frame's `estimate`.

mod wire;

pub use wire::{MAX_REPLY_HEADER_BYTES, PROTOCOL, VERSION};

use crate::estimator::{Estimate, PoseEstimator};
use crate::models::Mesh;
use crate::{PerceptionError, PerceptionFrame};
use std::io::{self, ErrorKind, Read, Write};
use std::os::unix::fs::FileTypeExt;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use wire::Reply;

/// Default time for the handshake (sending the mesh and the peer's `hello` reply): a GPU
/// estimator may load its networks and render the mesh before it answers.
pub const DEFAULT_HELLO_TIMEOUT: Duration = Duration::from_secs(60);
/// Default time for one frame (sending it and the whole reply): generous because a GPU
/// estimator's first frame (registration, kernel warm-up) can take several seconds.
pub const DEFAULT_FRAME_TIMEOUT: Duration = Duration::from_secs(30);
/// Default time for a `reset` and its reply.
pub const DEFAULT_RESET_TIMEOUT: Duration = Duration::from_secs(10);

/// Timeouts of the external estimator. Each bounds a whole exchange (request written and reply
/// read), not a single read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SocketConfig {
    pub hello_timeout: Duration,
    pub frame_timeout: Duration,
    pub reset_timeout: Duration,
}

impl Default for SocketConfig {
    fn default() -> Self {
        SocketConfig {
            hello_timeout: DEFAULT_HELLO_TIMEOUT,
            frame_timeout: DEFAULT_FRAME_TIMEOUT,
            reset_timeout: DEFAULT_RESET_TIMEOUT,
        }
    }
}

/// The client of an external estimator behind the [`PoseEstimator`] trait.
///
/// After a failure that leaves the byte stream in doubt (timeout, closed connection, anything out
/// of protocol) the connection is dropped and the next `estimate` connects again, with a fresh
/// `hello`; a peer's `error` reply keeps the connection. A new connection starts with no tracking
/// state, as after a reset.
pub struct SocketEstimator {
    path: PathBuf,
    config: SocketConfig,
    /// The encoded `hello` message (mesh inline), sent again on every reconnect.
    hello: Vec<u8>,
    stream: Option<UnixStream>,
    peer_name: String,
    reset_pending: bool,
    /// Reused buffer for outgoing frames.
    buf: Vec<u8>,
}

impl std::fmt::Debug for SocketEstimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SocketEstimator")
            .field("path", &self.path)
            .field("peer_name", &self.peer_name)
            .field("connected", &self.stream.is_some())
            .field("reset_pending", &self.reset_pending)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

/// A failure of one exchange: the message, and whether the connection is still in step.
struct Failure {
    msg: String,
    keep_connection: bool,
}

impl Failure {
    fn drop(msg: String) -> Failure {
        Failure { msg, keep_connection: false }
    }
    fn keep(msg: String) -> Failure {
        Failure { msg, keep_connection: true }
    }
}

impl From<String> for Failure {
    fn from(msg: String) -> Failure {
        Failure::drop(msg)
    }
}

impl SocketEstimator {
    /// Connects to the estimator listening on `path` and hands it `mesh` (the target, body frame,
    /// metres as the camera sees it) with the default timeouts.
    pub fn connect(path: &Path, mesh: &Mesh) -> Result<SocketEstimator, PerceptionError> {
        SocketEstimator::connect_with(path, mesh, SocketConfig::default())
    }

    /// [`SocketEstimator::connect`] with explicit timeouts.
    pub fn connect_with(
        path: &Path,
        mesh: &Mesh,
        config: SocketConfig,
    ) -> Result<SocketEstimator, PerceptionError> {
        let mut hello = Vec::new();
        wire::encode_hello(&mut hello, mesh);
        let mut est = SocketEstimator {
            path: path.to_path_buf(),
            config,
            hello,
            stream: None,
            peer_name: String::new(),
            reset_pending: false,
            buf: Vec::new(),
        };
        est.open().map_err(|msg| est.error(&msg))?;
        Ok(est)
    }

    /// The estimator's name from its `hello` reply.
    pub fn peer_name(&self) -> &str {
        &self.peer_name
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn config(&self) -> &SocketConfig {
        &self.config
    }

    fn error(&self, msg: &str) -> PerceptionError {
        PerceptionError::External(format!("socket {}: {msg}", self.path.display()))
    }

    /// Connects and shakes hands; on success the connection is `self.stream`.
    fn open(&mut self) -> Result<(), String> {
        self.stream = None;
        let mut stream =
            UnixStream::connect(&self.path).map_err(|e| connect_error(&self.path, &e))?;
        let limit = Limit { name: "hello timeout", value: self.config.hello_timeout };
        let deadline = Instant::now() + limit.value;
        send(&mut stream, &self.hello, deadline, "hello", limit)?;
        let hello = match receive(&mut stream, deadline, "hello", limit)? {
            Reply::Hello(h) => h,
            Reply::Error(reason) => {
                return Err(format!("the estimator refused the connection: {}", clip(&reason)))
            }
            other => {
                return Err(format!(
                    "expected a `hello` reply to hello, got `{}`",
                    other.type_name()
                ))
            }
        };
        if !hello.accept {
            let reason = hello.reason.as_deref().unwrap_or("no reason given");
            return Err(format!("the estimator refused the connection: {}", clip(reason)));
        }
        if hello.protocol != PROTOCOL || hello.version != VERSION {
            return Err(format!(
                "the estimator speaks {:?} version {}, this client speaks {PROTOCOL:?} version \
                 {VERSION}",
                clip(&hello.protocol),
                hello.version
            ));
        }
        let Some(name) = hello.estimator else {
            return Err("the `hello` reply accepts but lacks field `estimator` (its name)".into());
        };
        self.peer_name = clip(&name);
        self.stream = Some(stream);
        self.reset_pending = false;
        Ok(())
    }

    /// One frame: (re)connect if needed, send a pending reset, send the frame, read its reply.
    fn exchange(&mut self, frame: &PerceptionFrame) -> Result<Estimate, Failure> {
        if self.stream.is_none() {
            self.open().map_err(|e| Failure::drop(format!("reconnecting: {e}")))?;
        }
        let SocketEstimator { stream, config, reset_pending, buf, .. } = self;
        let Some(stream) = stream.as_mut() else {
            return Err(Failure::drop("not connected".into()));
        };
        let ctx = format!("frame {}", frame.seq);
        if std::mem::take(reset_pending) {
            let what = format!("reset before {ctx}");
            let limit = Limit { name: "reset timeout", value: config.reset_timeout };
            let deadline = Instant::now() + limit.value;
            buf.clear();
            wire::encode_reset(buf);
            send(stream, buf, deadline, &what, limit)?;
            match receive(stream, deadline, &what, limit)? {
                Reply::Reset => {}
                Reply::Error(r) => {
                    return Err(Failure::keep(format!(
                        "the estimator could not reset (before {ctx}): {}",
                        clip(&r)
                    )))
                }
                other => {
                    return Err(Failure::drop(format!(
                        "expected a `reset` reply to {what}, got `{}`",
                        other.type_name()
                    )))
                }
            }
        }
        let limit = Limit { name: "frame timeout", value: config.frame_timeout };
        let deadline = Instant::now() + limit.value;
        buf.clear();
        // The peer's camera model is a pinhole K: it gets the frame without the lens.
        wire::encode_frame(buf, &crate::undistort::to_pinhole(frame));
        send(stream, buf, deadline, &ctx, limit)?;
        match receive(stream, deadline, &ctx, limit)? {
            Reply::Pose(p) => {
                if p.seq != frame.seq {
                    return Err(Failure::drop(format!(
                        "the reply to {ctx} carries seq {} (out of step)",
                        p.seq
                    )));
                }
                wire::estimate_from(&p).map_err(|e| Failure::drop(format!("reply to {ctx}: {e}")))
            }
            Reply::Error(r) => {
                Err(Failure::keep(format!("the estimator failed on {ctx}: {}", clip(&r))))
            }
            other => Err(Failure::drop(format!(
                "expected a `pose` reply to {ctx}, got `{}`",
                other.type_name()
            ))),
        }
    }
}

impl PoseEstimator for SocketEstimator {
    fn name(&self) -> String {
        format!("socket:{}", self.path.display())
    }

    fn estimate(&mut self, frame: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        frame.validate()?;
        self.exchange(frame).map_err(|f| {
            if !f.keep_connection {
                self.stream = None;
            }
            self.error(&f.msg)
        })
    }

    /// Marks a reset for the next frame (no I/O here: see the module documentation).
    fn reset(&mut self) {
        if self.stream.is_some() {
            self.reset_pending = true;
        }
    }
}

/// A named timeout, for messages.
#[derive(Clone, Copy)]
struct Limit {
    name: &'static str,
    value: Duration,
}

fn connect_error(path: &Path, e: &io::Error) -> String {
    match e.kind() {
        ErrorKind::NotFound => "no socket at this path (start the estimator first)".into(),
        ErrorKind::ConnectionRefused => match std::fs::metadata(path) {
            Ok(m) if !m.file_type().is_socket() => {
                "this path is not a socket (start the estimator first)".into()
            }
            _ => "nothing is listening on this socket (start the estimator first)".into(),
        },
        ErrorKind::PermissionDenied => format!("no permission to connect ({e})"),
        _ => format!("cannot connect: {e}"),
    }
}

/// Peer text shown in messages: at most 200 characters.
fn clip(s: &str) -> String {
    match s.char_indices().nth(200) {
        Some((i, _)) => format!("{}...", &s[..i]),
        None => s.to_string(),
    }
}

enum IoFail {
    Timeout,
    /// End of stream (or reset) after `got` bytes of the current piece.
    Closed {
        got: usize,
    },
    Other(io::Error),
}

fn is_timeout(e: &io::Error) -> bool {
    matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut)
}

fn is_closed(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        ErrorKind::BrokenPipe | ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted
    )
}

fn remaining(deadline: Instant) -> Option<Duration> {
    Some(deadline.saturating_duration_since(Instant::now())).filter(|d| !d.is_zero())
}

fn write_all_by(
    stream: &mut UnixStream,
    mut bytes: &[u8],
    deadline: Instant,
) -> Result<(), IoFail> {
    while !bytes.is_empty() {
        let left = remaining(deadline).ok_or(IoFail::Timeout)?;
        stream.set_write_timeout(Some(left)).map_err(IoFail::Other)?;
        match stream.write(bytes) {
            Ok(0) => return Err(IoFail::Closed { got: 0 }),
            Ok(n) => bytes = &bytes[n..],
            Err(e) if e.kind() == ErrorKind::Interrupted || is_timeout(&e) => {}
            Err(e) if is_closed(&e) => return Err(IoFail::Closed { got: 0 }),
            Err(e) => return Err(IoFail::Other(e)),
        }
    }
    Ok(())
}

fn read_exact_by(stream: &mut UnixStream, buf: &mut [u8], deadline: Instant) -> Result<(), IoFail> {
    let mut got = 0;
    while got < buf.len() {
        let left = remaining(deadline).ok_or(IoFail::Timeout)?;
        stream.set_read_timeout(Some(left)).map_err(IoFail::Other)?;
        match stream.read(&mut buf[got..]) {
            Ok(0) => return Err(IoFail::Closed { got }),
            Ok(n) => got += n,
            Err(e) if e.kind() == ErrorKind::Interrupted || is_timeout(&e) => {}
            Err(e) if is_closed(&e) => return Err(IoFail::Closed { got }),
            Err(e) => return Err(IoFail::Other(e)),
        }
    }
    Ok(())
}

fn send(
    stream: &mut UnixStream,
    bytes: &[u8],
    deadline: Instant,
    what: &str,
    limit: Limit,
) -> Result<(), String> {
    write_all_by(stream, bytes, deadline).map_err(|f| match f {
        IoFail::Timeout => format!(
            "could not send {what} within {:?} (the {}): the estimator is not reading",
            limit.value, limit.name
        ),
        IoFail::Closed { .. } => {
            format!("the estimator closed the connection while {what} was being sent")
        }
        IoFail::Other(e) => format!("sending {what}: {e}"),
    })
}

/// Reads one reply: length, header (at most [`MAX_REPLY_HEADER_BYTES`]), decoded and checked.
fn receive(
    stream: &mut UnixStream,
    deadline: Instant,
    what: &str,
    limit: Limit,
) -> Result<Reply, String> {
    let timeout =
        || format!("no complete reply to {what} within {:?} (the {})", limit.value, limit.name);
    let mut len = [0u8; 4];
    read_exact_by(stream, &mut len, deadline).map_err(|f| match f {
        IoFail::Timeout => timeout(),
        IoFail::Closed { got: 0 } => {
            format!("the estimator closed the connection before replying to {what}")
        }
        IoFail::Closed { got } => format!(
            "the estimator closed the connection in the middle of its reply to {what} \
             ({got} of 4 length bytes)"
        ),
        IoFail::Other(e) => format!("reading the reply to {what}: {e}"),
    })?;
    let n = u32::from_le_bytes(len) as usize;
    if n == 0 {
        return Err(format!("the reply to {what} has an empty header (length 0)"));
    }
    if n > MAX_REPLY_HEADER_BYTES {
        return Err(format!(
            "the reply to {what} announces a {n}-byte header, which exceeds the 1 MiB limit \
             (not a {PROTOCOL} peer, or out of step)"
        ));
    }
    let mut header = vec![0u8; n];
    read_exact_by(stream, &mut header, deadline).map_err(|f| match f {
        IoFail::Timeout => timeout(),
        IoFail::Closed { got } => format!(
            "the estimator closed the connection in the middle of its reply to {what} \
             ({got} of {n} header bytes)"
        ),
        IoFail::Other(e) => format!("reading the reply to {what}: {e}"),
    })?;
    wire::decode_reply(&header).map_err(|e| format!("reply to {what}: {e}"))
}
