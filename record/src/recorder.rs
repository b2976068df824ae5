//! The recorder thread: drains the queues into the MCAP file, flushes chunks often, reports
//! its health, and closes the file with its summary.
//!
//! It runs on its own OS thread rather than a tokio task: compression and file writes block
//! and burn CPU, which must not stall the async runtime's other tasks (perception, camera
//! intake, signals).

use crate::channels::CHANNELS;
use crate::compression::ChunkCompression;
use crate::error::RecordError;
use crate::health::RecorderHealth;
use crate::live::LiveTap;
use crate::metadata::RunMetadata;
use crate::msg::{EventKind, SafetyEventMsg};
use crate::queues::{QueueCapacity, Telemetry, COUNTED_TOPICS};
use crate::sink::{DepthOutput, McapSink};
use crate::summary::RecordSummary;
use crate::topics;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How the recorder writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecorderConfig {
    pub queues: QueueCapacity,
    pub compression: ChunkCompression,
    /// zstd worker threads (0: compress on the recorder thread).
    pub compression_threads: u32,
    /// A chunk closes once it holds this many bytes (uncompressed).
    pub chunk_size: u64,
    /// Open chunks are closed and handed to the OS at least this often (crash safety: a kill
    /// loses at most this much, plus what sat in the queues).
    pub flush_interval: Duration,
    /// `/recorder/stats` period.
    pub stats_interval: Duration,
    pub depth_output: DepthOutput,
}

impl Default for RecorderConfig {
    fn default() -> Self {
        Self {
            queues: QueueCapacity::default(),
            // lz4: about 1.26x the frames per CPU second of zstd level 1 on camera-sized frames,
            // at a lower ratio (docs/mcap-topics.md has the figures); the others stay selectable.
            compression: ChunkCompression::Lz4,
            compression_threads: 1,
            chunk_size: 4 << 20,
            flush_interval: Duration::from_millis(250),
            stats_interval: Duration::from_secs(1),
            depth_output: DepthOutput::AsDelivered,
        }
    }
}

/// Starts recorders.
pub struct Recorder;

/// The control side of a running recorder.
pub struct RecorderHandle {
    health: RecorderHealth,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<RecordSummary>>,
    telemetry: Telemetry,
}

impl Recorder {
    /// Create the file, write the `run` metadata and start the recorder thread.
    pub fn spawn(
        path: impl AsRef<Path>,
        meta: &RunMetadata,
    ) -> Result<(RecorderHandle, Telemetry), RecordError> {
        Self::spawn_with(path, meta, RecorderConfig::default())
    }

    /// [`Recorder::spawn`] with explicit settings.
    pub fn spawn_with(
        path: impl AsRef<Path>,
        meta: &RunMetadata,
        cfg: RecorderConfig,
    ) -> Result<(RecorderHandle, Telemetry), RecordError> {
        Self::spawn_live(path, meta, cfg, None)
    }

    /// [`Recorder::spawn_with`], also streaming what it writes to a live view (`hitl run --live`,
    /// see [`crate::live`]).
    pub fn spawn_live(
        path: impl AsRef<Path>,
        meta: &RunMetadata,
        cfg: RecorderConfig,
        live: Option<LiveTap>,
    ) -> Result<(RecorderHandle, Telemetry), RecordError> {
        let path = path.as_ref().to_path_buf();
        let mut sink = McapSink::create(
            &path,
            meta,
            cfg.compression,
            cfg.compression_threads,
            cfg.chunk_size,
            cfg.depth_output,
        )?;
        sink.live = live;
        let telemetry = Telemetry::new(cfg.queues);
        let health = RecorderHealth::default();
        let stop = Arc::new(AtomicBool::new(false));
        let worker = Worker {
            sink: Some(sink),
            tel: telemetry.clone(),
            health: health.clone(),
            stop: stop.clone(),
            cfg,
            path,
            last_t_ns: 0,
            failure: None,
            written: [0; CHANNELS.len()],
            bytes_in: 0,
        };
        let thread = std::thread::Builder::new()
            .name("hitl-recorder".into())
            .spawn(move || worker.run())
            .map_err(RecordError::Spawn)?;
        Ok((
            RecorderHandle { health, stop, thread: Some(thread), telemetry: telemetry.clone() },
            telemetry,
        ))
    }
}

impl RecorderHandle {
    /// The health flag (clone it into the control loop; `is_failed()` is lock-free).
    pub fn health(&self) -> RecorderHealth {
        self.health.clone()
    }

    /// Another handle on the queues.
    pub fn telemetry(&self) -> Telemetry {
        self.telemetry.clone()
    }

    /// Write what is queued, the counters and the summary, and close the file.
    /// `Err(RecordError::Failed)` when the recorder had stopped writing during the run.
    pub fn finish(mut self) -> Result<RecordSummary, RecordError> {
        let summary = self.stop_and_join()?;
        match summary.failure.clone() {
            Some(reason) => Err(RecordError::Failed { reason, summary: Box::new(summary) }),
            None => Ok(summary),
        }
    }

    fn stop_and_join(&mut self) -> Result<RecordSummary, RecordError> {
        self.stop.store(true, Ordering::Release);
        match self.thread.take() {
            Some(t) => t.join().map_err(|_| RecordError::Panicked),
            None => Err(RecordError::Panicked),
        }
    }
}

impl Drop for RecorderHandle {
    /// A handle dropped without `finish` (an early return, a panic) still closes the file.
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.stop_and_join();
        }
    }
}

/// An error with its causes ("MCAP writer: I/O error: File too large (os error 27)").
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        let c_s = c.to_string();
        if !s.contains(&c_s) {
            s.push_str(": ");
            s.push_str(&c_s);
        }
        cur = c.source();
    }
    s
}

struct Worker {
    sink: Option<McapSink>,
    tel: Telemetry,
    health: RecorderHealth,
    stop: Arc<AtomicBool>,
    cfg: RecorderConfig,
    path: PathBuf,
    /// Latest message time seen (stamps the recorder's own messages).
    last_t_ns: u64,
    failure: Option<String>,
    written: [u64; CHANNELS.len()],
    bytes_in: u64,
}

impl Worker {
    fn run(mut self) -> RecordSummary {
        let start = Instant::now();
        let mut last_flush = Instant::now();
        let mut last_stats = Instant::now();
        let mut dirty = false;
        loop {
            let stopping = self.stop.load(Ordering::Acquire);
            let mut n = self.drain_telemetry();
            // One frame per pass, so telemetry keeps flowing between large frames.
            if let Some(f) = self.tel.q.frames.pop() {
                n += 1;
                self.last_t_ns = self.last_t_ns.max(f.capture_ns);
                let tick = f.tick;
                let r = self.with_sink(|s| s.frame(f));
                if let Some(Some(bad)) = r {
                    let ev = SafetyEventMsg::text(self.last_t_ns, EventKind::FrameMalformed, bad);
                    let _ = tick;
                    self.with_sink(|s| s.event(&ev));
                }
            }
            dirty |= n > 0;
            if dirty && last_flush.elapsed() >= self.cfg.flush_interval {
                self.with_sink(|s| s.flush());
                last_flush = Instant::now();
                dirty = false;
            }
            if last_stats.elapsed() >= self.cfg.stats_interval {
                let v = self.stats_json();
                let t = self.last_t_ns;
                self.with_sink(|s| s.stats(t, &v));
                dirty = true;
                last_stats = Instant::now();
            }
            if stopping && n == 0 && self.tel.q.frames.is_empty() {
                break;
            }
            if n == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        self.tel.q.closed.store(true, Ordering::Release);
        // Whatever was pushed between the last pass and `closed`.
        self.drain_telemetry();
        while let Some(f) = self.tel.q.frames.pop() {
            self.with_sink(|s| s.frame(f));
        }
        self.close();
        let mut s = self.summary();
        s.elapsed_s = start.elapsed().as_secs_f64();
        s
    }

    /// Run one write; on an I/O or MCAP failure mark the recorder failed and stop writing.
    fn with_sink<T>(
        &mut self,
        f: impl FnOnce(&mut McapSink) -> Result<T, RecordError>,
    ) -> Option<T> {
        let sink = self.sink.as_mut()?;
        match f(sink) {
            Ok(v) => {
                self.written = sink.written;
                self.bytes_in = sink.bytes_in;
                Some(v)
            }
            Err(e @ (RecordError::Encode(_) | RecordError::Json(_))) => {
                // One message that cannot be encoded is not a failed recorder.
                let ev = SafetyEventMsg::text(self.last_t_ns, EventKind::Other, e.to_string());
                let _ = sink.event(&ev);
                None
            }
            Err(e) => {
                let reason = format!("{}: {}", self.path.display(), error_chain(&e));
                self.health.set_failed(reason.clone());
                self.failure = Some(reason);
                self.tel.q.closed.store(true, Ordering::Release);
                // Dropping the writer tries to close it; in its failed state it writes nothing
                // more, so what reached the file before stays readable.
                self.sink = None;
                None
            }
        }
    }

    fn drain_telemetry(&mut self) -> usize {
        let mut n = 0;
        let q = self.tel.q.clone();
        let pending = q.metadata.lock().map(|mut m| std::mem::take(&mut *m)).unwrap_or_default();
        for (name, map) in pending {
            n += 1;
            self.with_sink(|s| s.write_metadata(&name, map));
        }
        while let Some(m) = q.setpoint.pop() {
            n += 1;
            self.last_t_ns = self.last_t_ns.max(m.t_ns);
            self.with_sink(|s| s.setpoint(&m));
        }
        while let Some(m) = q.state.pop() {
            n += 1;
            self.last_t_ns = self.last_t_ns.max(m.t_ns);
            self.with_sink(|s| s.state(&m));
        }
        while let Some(m) = q.timing.pop() {
            n += 1;
            self.last_t_ns = self.last_t_ns.max(m.t_ns);
            self.with_sink(|s| s.timing(&m));
        }
        while let Some(m) = q.light.pop() {
            n += 1;
            self.with_sink(|s| s.light(&m));
        }
        while let Some(m) = q.fired.pop() {
            n += 1;
            self.with_sink(|s| s.trigger_fired(&m));
        }
        while let Some(m) = q.tf.pop() {
            n += 1;
            self.with_sink(|s| s.tf(&m));
        }
        while let Some(m) = q.estimate.pop() {
            n += 1;
            self.with_sink(|s| s.pose_estimate(&m));
        }
        while let Some(m) = q.event.pop() {
            n += 1;
            self.with_sink(|s| s.event(&m));
        }
        while let Some(m) = q.closed_loop.pop() {
            n += 1;
            self.with_sink(|s| s.closed_loop(&m));
        }
        n
    }

    fn stats_json(&self) -> serde_json::Value {
        let s = self.summary();
        serde_json::json!({
            "t_ns": self.last_t_ns,
            "written": s.written,
            "dropped": s.dropped,
            "frames_not_recorded": s.frames_not_recorded,
            "bytes_in": s.bytes_in,
        })
    }

    fn close(&mut self) {
        let v = self.stats_json();
        let t = self.last_t_ns;
        self.with_sink(|s| s.stats(t, &v));
        let mut m = BTreeMap::new();
        if let serde_json::Value::Object(o) = &v {
            for (k, val) in o {
                m.insert(k.clone(), val.to_string());
            }
        }
        self.with_sink(|s| s.write_metadata(topics::META_RECORDER_STATS, m));
        if let Some(sink) = self.sink.take() {
            match sink.finish() {
                Ok(()) => self.health.set_closed(),
                Err(e) => {
                    let reason = format!("{}: closing: {}", self.path.display(), error_chain(&e));
                    self.health.set_failed(reason.clone());
                    self.failure = Some(reason);
                }
            }
        }
    }

    fn summary(&self) -> RecordSummary {
        let written = CHANNELS
            .iter()
            .enumerate()
            .map(|(i, c)| (c.topic().to_string(), self.written[i]))
            .collect();
        let dropped = COUNTED_TOPICS
            .iter()
            .map(|(c, name)| {
                (name.to_string(), self.tel.q.drops[*c as usize].load(Ordering::Relaxed))
            })
            .collect();
        RecordSummary {
            path: self.path.clone(),
            written,
            dropped,
            frames_not_recorded: self.tel.frames_not_recorded(),
            bytes_in: self.bytes_in,
            file_bytes: std::fs::metadata(&self.path).map(|m| m.len()).unwrap_or(0),
            elapsed_s: 0.0,
            failure: self.failure.clone(),
        }
    }
}
