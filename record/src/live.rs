//! The live view of a run (`hitl run --live`): the recording's messages, streamed to Foxglove over
//! its WebSocket protocol (subprotocol `foxglove.sdk.v1`) while the run goes on.
//!
//! - What is streamed comes from the recorder thread, never from the tick: the MCAP sink hands
//!   [`LiveTap`] the bytes it has just written (same topics, encodings and schemas as the file,
//!   docs/mcap-topics.md), and the camera frames it is about to write.
//! - With no viewer subscribed to a topic, its messages cost one atomic load each (the channel's
//!   "has sinks" state): nothing is copied or encoded for the live view.
//! - Telemetry, `/tf` and the poses go at full rate. `/camera/color` (with a `/camera/calibration`
//!   scaled to match) is decimated to at most one image per [`LiveConfig::image_period`] of
//!   capture time and shrunk by a whole factor to at most [`LiveConfig::image_max_width`] pixels;
//!   depth and mask stay in the recording only.
//! - Memory is bounded twice: between the recorder and the server, a hand-off queue of
//!   [`LiveConfig::handoff`] messages (a message that finds it full is dropped and counted:
//!   `live dropped` in the run summary), and in the server, [`LiveConfig::backlog`] messages per
//!   viewer (the `foxglove` crate drops the oldest for a viewer that falls behind; it does not
//!   count them).
//! - Read-only: the server advertises no capability (no client publishing, no services, no
//!   parameters).
//!
//! The server's tasks run on the tokio runtime it is started from ([`LiveServer::start`] takes
//! its handle); the hand-off is drained by a thread of its own (`hitl-live`), so the recorder
//! never waits on a viewer's socket or on the server's locks.

use crate::channels::{Ch, CHANNELS};
use crate::topics;
use foxglove::messages as fg;
use foxglove::websocket::ServerListener;
use foxglove::{Context, Encode, PartialMetadata, RawChannel, Schema, WebSocketServer};
use serde::Serialize;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// The live view's address when `--live` names none: loopback, Foxglove's usual port.
pub const DEFAULT_LIVE_ADDR: SocketAddr = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 8765);

/// How the live view serves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveConfig {
    /// Where the WebSocket server listens (port 0: any free port).
    pub addr: SocketAddr,
    /// Least capture time between two live camera images.
    pub image_period: Duration,
    /// Live images wider than this are shrunk by the smallest whole factor that fits (box filter).
    pub image_max_width: u32,
    /// Messages the server queues per viewer before it drops the oldest.
    pub backlog: usize,
    /// Messages waiting between the recorder and the server before new ones are dropped.
    pub handoff: usize,
}

impl LiveConfig {
    /// The defaults at `addr`: 5 images/s at most 320 px wide; 512 messages per viewer (about
    /// 0.7 s of full-rate telemetry at 250 Hz, or 126 MB if every one were a 320x256 image); a
    /// 1024-message hand-off.
    pub fn new(addr: SocketAddr) -> Self {
        Self {
            addr,
            image_period: Duration::from_millis(200),
            image_max_width: 320,
            backlog: 512,
            handoff: 1024,
        }
    }
}

/// The live view could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error("live view: cannot listen on {addr}: {reason}")]
    Listen { addr: SocketAddr, reason: String },
    #[error("live view: {0}")]
    Start(String),
}

/// What the live view did, for the run summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct LiveSummary {
    /// Where it listened.
    pub addr: SocketAddr,
    /// Viewers that connected during the run.
    pub viewers: u64,
    /// Messages handed to the server (each goes to every viewer subscribed to its topic).
    pub sent: u64,
    /// Of which camera images.
    pub images: u64,
    /// Messages dropped because the hand-off to the server was full.
    pub dropped: u64,
}

#[derive(Debug, Default)]
struct Counters {
    viewers: AtomicU64,
    sent: AtomicU64,
    images: AtomicU64,
    dropped: AtomicU64,
}

/// Counts the viewers that connect (the server's only callback the live view uses).
struct ViewerCount(Arc<Counters>);

impl ServerListener for ViewerCount {
    fn on_client_connect(&self) {
        self.0.viewers.fetch_add(1, Ordering::Relaxed);
    }
}

/// One message on its way to the server.
struct LiveMsg {
    ch: Ch,
    log_time: u64,
    data: Vec<u8>,
}

/// Whether a channel of the recording is offered live at all.
fn is_live(ch: Ch) -> bool {
    !matches!(ch, Ch::Depth | Ch::Mask)
}

/// The running server. Close it after the recorder has finished (its tap is then gone).
pub struct LiveServer {
    handle: Option<foxglove::WebSocketServerHandle>,
    runtime: tokio::runtime::Handle,
    addr: SocketAddr,
    counters: Arc<Counters>,
    forwarder: Option<JoinHandle<()>>,
    // Keeps the channels advertised until the server stops.
    _context: Arc<Context>,
}

impl LiveServer {
    /// Listen on `cfg.addr` with every live channel of the recording advertised, the server's
    /// tasks on `runtime`. The tap goes to the recorder ([`crate::Recorder::spawn_live`]).
    pub fn start(
        cfg: LiveConfig,
        runtime: &tokio::runtime::Handle,
    ) -> Result<(LiveServer, LiveTap), LiveError> {
        let context = Context::new();
        let mut channels: [Option<Arc<RawChannel>>; CHANNELS.len()] = Default::default();
        for ch in CHANNELS.into_iter().filter(|c| is_live(*c)) {
            let (name, encoding, data) =
                ch.schema().map_err(|e| LiveError::Start(e.to_string()))?;
            let message_encoding = if encoding == "protobuf" { "protobuf" } else { "json" };
            let channel = context
                .channel_builder(ch.topic())
                .message_encoding(message_encoding)
                .schema(Schema::new(name, encoding, data))
                .build_raw()
                .map_err(|e| LiveError::Start(format!("{}: {e}", ch.topic())))?;
            channels[ch as usize] = Some(channel);
        }
        let counters = Arc::new(Counters::default());
        // A v6 literal needs its brackets in the "host:port" the server binds.
        let host = match cfg.addr.ip() {
            IpAddr::V4(ip) => ip.to_string(),
            IpAddr::V6(ip) => format!("[{ip}]"),
        };
        let server = WebSocketServer::new()
            .name("hitl")
            .context(&context)
            .bind(host, cfg.addr.port())
            .message_backlog_size(cfg.backlog.max(1))
            .listener(Arc::new(ViewerCount(Arc::clone(&counters))));
        // Started inside the runtime, the server spawns its tasks on it.
        let handle = runtime.block_on(server.start()).map_err(|e| match e {
            foxglove::FoxgloveError::Bind(io) => {
                LiveError::Listen { addr: cfg.addr, reason: io.to_string() }
            }
            other => LiveError::Start(other.to_string()),
        })?;
        let addr = SocketAddr::new(cfg.addr.ip(), handle.port());
        let (tx, rx) = mpsc::sync_channel(cfg.handoff.max(1));
        let forward_to = channels.clone();
        let forwarder = std::thread::Builder::new()
            .name("hitl-live".into())
            .spawn(move || forward(rx, &forward_to))
            .map_err(|e| LiveError::Start(format!("live thread: {e}")))?;
        let tap = LiveTap { channels, tx, counters: Arc::clone(&counters), cfg, last_image: None };
        Ok((
            LiveServer {
                handle: Some(handle),
                runtime: runtime.clone(),
                addr,
                counters,
                forwarder: Some(forwarder),
                _context: context,
            },
            tap,
        ))
    }

    /// Where the server listens (with the port it got for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stop serving: viewers are disconnected, the server's tasks end (up to 2 s), and the
    /// hand-off thread is joined once the recorder has dropped its tap.
    pub fn close(mut self) -> LiveSummary {
        self.stop_server();
        if let Some(t) = self.forwarder.take() {
            let _ = t.join();
        }
        let c = &self.counters;
        LiveSummary {
            addr: self.addr,
            viewers: c.viewers.load(Ordering::Relaxed),
            sent: c.sent.load(Ordering::Relaxed),
            images: c.images.load(Ordering::Relaxed),
            dropped: c.dropped.load(Ordering::Relaxed),
        }
    }

    fn stop_server(&mut self) {
        if let Some(h) = self.handle.take() {
            let shutdown = h.stop();
            self.runtime.block_on(async {
                let _ = tokio::time::timeout(Duration::from_secs(2), shutdown.wait()).await;
            });
        }
    }
}

impl Drop for LiveServer {
    /// A run that ends early still closes the port; the hand-off thread ends with the tap.
    fn drop(&mut self) {
        self.stop_server();
    }
}

/// The hand-off thread: log each message on its channel until the tap is dropped.
fn forward(rx: Receiver<LiveMsg>, channels: &[Option<Arc<RawChannel>>; CHANNELS.len()]) {
    while let Ok(m) = rx.recv() {
        if let Some(c) = &channels[m.ch as usize] {
            c.log_with_meta(&m.data, PartialMetadata::with_log_time(m.log_time));
        }
    }
}

/// The recorder's side of the live view: owned by the MCAP sink, called on the recorder thread.
pub struct LiveTap {
    channels: [Option<Arc<RawChannel>>; CHANNELS.len()],
    tx: SyncSender<LiveMsg>,
    counters: Arc<Counters>,
    cfg: LiveConfig,
    /// Capture time of the last live image.
    last_image: Option<u64>,
}

impl LiveTap {
    /// A viewer is subscribed to `ch`.
    fn wanted(&self, ch: Ch) -> Option<&Arc<RawChannel>> {
        self.channels[ch as usize].as_ref().filter(|c| c.has_sinks())
    }

    fn send(&self, ch: Ch, log_time: u64, data: Vec<u8>) -> bool {
        match self.tx.try_send(LiveMsg { ch, log_time, data }) {
            Ok(()) => {
                self.counters.sent.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.counters.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// A message the sink has just written: forwarded as it is when a viewer wants its topic.
    /// Camera topics go through [`LiveTap::frame`] instead.
    pub(crate) fn offer(&self, ch: Ch, log_time: u64, data: &[u8]) {
        if matches!(ch, Ch::Color | Ch::Depth | Ch::Mask | Ch::Calibration) {
            return;
        }
        if self.wanted(ch).is_some() {
            self.send(ch, log_time, data.to_vec());
        }
    }

    /// A capture about to be written: its colour image (shrunk) and the calibration that matches
    /// it, when a viewer wants them and the last live image is at least `image_period` old.
    pub(crate) fn frame(&mut self, f: &crate::msg::FrameRecord) {
        let color = f.color.as_ref().filter(|c| c.is_consistent(3) && c.width > 0);
        let want_color = color.is_some() && self.wanted(Ch::Color).is_some();
        let want_cal = self.wanted(Ch::Calibration).is_some();
        if !want_color && !want_cal {
            return;
        }
        let t = f.capture_ns;
        let period = u64::try_from(self.cfg.image_period.as_nanos()).unwrap_or(u64::MAX);
        if self.last_image.is_some_and(|last| t < last.saturating_add(period)) {
            return;
        }
        self.last_image = Some(t);
        let width = color.map_or(f.intrinsics.width, |c| c.width);
        let factor = width.div_ceil(self.cfg.image_max_width.max(1)).max(1);
        if let (true, Some(c)) = (want_color, color) {
            let (w, h, px) = shrink_rgb8(&c.data, c.width, c.height, factor);
            let msg = fg::RawImage {
                timestamp: crate::channels::ts(t),
                frame_id: topics::FRAME_CAMERA.to_string(),
                width: w,
                height: h,
                encoding: "rgb8".to_string(),
                step: w * 3,
                data: bytes::Bytes::from(px),
            };
            if let Some(buf) = encode(&msg) {
                if self.send(Ch::Color, t, buf) {
                    self.counters.images.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if want_cal {
            let cal = crate::channels::calibration(&f.intrinsics, t, factor);
            if let Some(buf) = encode(&cal) {
                self.send(Ch::Calibration, t, buf);
            }
        }
    }
}

fn encode<T: Encode>(m: &T) -> Option<Vec<u8>> {
    let mut buf = Vec::with_capacity(m.encoded_len().unwrap_or(256));
    m.encode(&mut buf).ok()?;
    Some(buf)
}

/// An rgb8 image shrunk by `factor` in both directions, each output pixel the mean of its
/// `factor` x `factor` block (a partial last row or column of blocks is left out).
fn shrink_rgb8(data: &[u8], width: u32, height: u32, factor: u32) -> (u32, u32, Vec<u8>) {
    if factor <= 1 {
        return (width, height, data.to_vec());
    }
    let (w, h, f) = (width / factor, height / factor, factor as usize);
    let mut out = Vec::with_capacity(w as usize * h as usize * 3);
    let n = (f * f) as u32;
    for y in 0..h as usize {
        for x in 0..w as usize {
            let mut sum = [0u32; 3];
            for dy in 0..f {
                let row = (y * f + dy) * width as usize;
                for dx in 0..f {
                    let i = (row + x * f + dx) * 3;
                    for (s, v) in sum.iter_mut().zip(&data[i..i + 3]) {
                        *s += u32::from(*v);
                    }
                }
            }
            out.extend(sum.map(|s| ((s + n / 2) / n) as u8));
        }
    }
    (w, h, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shrinking_averages_whole_blocks() {
        // 5x2 image, factor 2: two output pixels (the fifth column is left out).
        let mut data = Vec::new();
        for v in [0u8, 10, 100, 110, 255, 20, 30, 120, 130, 255] {
            data.extend([v, v / 2, 255 - v]);
        }
        let (w, h, px) = shrink_rgb8(&data, 5, 2, 2);
        assert_eq!((w, h), (2, 1));
        // (0 + 10 + 20 + 30) / 4 = 15; (100 + 110 + 120 + 130) / 4 = 115.
        assert_eq!(px, vec![15, 8, 240, 115, 58, 140]);
        let (w, h, same) = shrink_rgb8(&data, 5, 2, 1);
        assert_eq!((w, h, same), (5, 2, data));
    }

    #[test]
    fn a_port_in_use_is_a_listen_error_naming_the_address() {
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().expect("rt");
        let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let addr = taken.local_addr().expect("addr");
        match LiveServer::start(LiveConfig::new(addr), rt.handle()) {
            Err(LiveError::Listen { addr: a, reason }) => {
                assert_eq!(a, addr);
                assert!(reason.to_lowercase().contains("in use"), "{reason}");
            }
            Err(e) => panic!("wrong error: {e}"),
            Ok(_) => panic!("listened on a port in use"),
        }
    }
}
