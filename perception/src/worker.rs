//! The asynchronous perception worker (tokio).
//!
//! The capture path pushes frames into a bounded [`FrameQueue`] that never blocks: when it is
//! full the OLDEST frame is dropped and counted (a lock-free `crossbeam` ring with
//! `force_push`). One worker task takes frames in order and runs the backend on tokio's blocking
//! pool, so the async threads never stall on a pose solve; each result goes out on a bounded
//! channel stamped with the frame's timestamp (the lead writes it to `/pose/estimate`).
//!
//! Re-registration follows a [`ReregisterPolicy`] through [`Reregistering`], the same driver
//! `hitl eval --backend` replays with.

use crate::estimator::{Estimate, PoseEstimator};
use crate::reregister::{ReregisterPolicy, Reregistering};
use crate::PerceptionFrame;
use crossbeam_queue::ArrayQueue;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use tokio::sync::{mpsc, Notify};
use tokio::task::JoinHandle;

/// Counters of the worker, readable at any time.
#[derive(Debug, Default)]
pub struct WorkerStats {
    pub pushed: AtomicU64,
    /// Frames dropped because the queue was full (the oldest went).
    pub dropped: AtomicU64,
    pub estimated: AtomicU64,
    pub lost: AtomicU64,
    pub errors: AtomicU64,
    /// Resets forced by the policy or by a lost frame.
    pub resets: AtomicU64,
    /// Results not delivered because the consumer had gone.
    pub undelivered: AtomicU64,
    /// The worker has ended (closed, or its backend panicked): a frame pushed now is never
    /// estimated.
    pub ended: AtomicBool,
}

impl WorkerStats {
    pub fn to_json(&self) -> serde_json::Value {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        serde_json::json!({
            "pushed": g(&self.pushed), "dropped": g(&self.dropped), "estimated": g(&self.estimated),
            "lost": g(&self.lost), "errors": g(&self.errors), "resets": g(&self.resets),
            "undelivered": g(&self.undelivered),
        })
    }
}

/// One frame's result, stamped with the frame's timestamp.
#[derive(Debug, Clone)]
pub struct PoseResult {
    pub timestamp_ns: u64,
    pub seq: u64,
    /// `Err` carries the backend's error message (bad frame, runtime failure).
    pub estimate: Result<Estimate, String>,
    /// Wall time the backend took, nanoseconds.
    pub solve_ns: u64,
}

/// The bounded drop-oldest queue between the capture path and the worker.
pub struct FrameQueue {
    ring: ArrayQueue<PerceptionFrame>,
    notify: Notify,
    closed: AtomicBool,
    stats: Arc<WorkerStats>,
}

impl FrameQueue {
    fn new(capacity: usize, stats: Arc<WorkerStats>) -> Self {
        FrameQueue {
            ring: ArrayQueue::new(capacity.max(1)),
            notify: Notify::new(),
            closed: AtomicBool::new(false),
            stats,
        }
    }

    /// Hands a frame to the worker; never blocks. Returns true if an older frame was dropped.
    pub fn push(&self, frame: PerceptionFrame) -> bool {
        self.stats.pushed.fetch_add(1, Ordering::Relaxed);
        let dropped = self.ring.force_push(frame).is_some();
        if dropped {
            self.stats.dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.notify.notify_one();
        dropped
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.ring.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ring.is_empty()
    }
}

/// The capture side's handle: push frames, read counters, close.
#[derive(Clone)]
pub struct WorkerHandle {
    pub queue: Arc<FrameQueue>,
    pub stats: Arc<WorkerStats>,
}

impl WorkerHandle {
    /// Hands a frame over (never blocks; drops the oldest when full).
    pub fn push(&self, frame: PerceptionFrame) -> bool {
        self.queue.push(frame)
    }

    /// No more frames: the worker finishes the queued ones and ends.
    pub fn close(&self) {
        self.queue.closed.store(true, Ordering::Release);
        self.queue.notify.notify_one();
    }
}

/// Starts the worker on the current tokio runtime. Results go to the returned receiver
/// (capacity `results_capacity`; a slow consumer stalls only the worker, whose queue then drops).
pub fn spawn_worker(
    estimator: Box<dyn PoseEstimator>,
    queue_capacity: usize,
    results_capacity: usize,
    policy: ReregisterPolicy,
) -> (WorkerHandle, mpsc::Receiver<PoseResult>, JoinHandle<()>) {
    let stats = Arc::new(WorkerStats::default());
    let queue = Arc::new(FrameQueue::new(queue_capacity, stats.clone()));
    let (tx, rx) = mpsc::channel(results_capacity.max(1));
    let handle = WorkerHandle { queue: queue.clone(), stats: stats.clone() };
    let task = tokio::spawn(async move {
        run(Reregistering::new(estimator, policy), queue, &stats, tx).await;
        stats.ended.store(true, Ordering::Release);
    });
    (handle, rx, task)
}

async fn run(
    mut driven: Reregistering,
    queue: Arc<FrameQueue>,
    stats: &WorkerStats,
    tx: mpsc::Sender<PoseResult>,
) {
    loop {
        let frame = match queue.ring.pop() {
            Some(f) => f,
            None => {
                if queue.closed.load(Ordering::Acquire) {
                    break;
                }
                // A push between pop() and here leaves a stored permit, so this cannot hang.
                queue.notify.notified().await;
                continue;
            }
        };
        let (ts, seq) = (frame.timestamp_ns, frame.seq);
        let joined = tokio::task::spawn_blocking(move || {
            let t0 = std::time::Instant::now();
            let (r, resets) = driven.estimate(&frame);
            (driven, r, resets, t0.elapsed().as_nanos() as u64)
        })
        .await;
        let (back, result, resets, solve_ns) = match joined {
            Ok(v) => v,
            Err(e) => {
                // The backend panicked: nothing left to run; report and stop.
                stats.errors.fetch_add(1, Ordering::Relaxed);
                let _ = tx
                    .send(PoseResult {
                        timestamp_ns: ts,
                        seq,
                        estimate: Err(format!("perception backend panicked: {e}")),
                        solve_ns: 0,
                    })
                    .await;
                return;
            }
        };
        driven = back;
        stats.resets.fetch_add(u64::from(resets), Ordering::Relaxed);
        let estimate = match result {
            Ok(e) => {
                stats.estimated.fetch_add(1, Ordering::Relaxed);
                if e.pose.is_none() {
                    stats.lost.fetch_add(1, Ordering::Relaxed);
                }
                Ok(e)
            }
            Err(err) => {
                stats.errors.fetch_add(1, Ordering::Relaxed);
                Err(err.to_string())
            }
        };
        let r = PoseResult { timestamp_ns: ts, seq, estimate, solve_ns };
        if tx.send(r).await.is_err() {
            stats.undelivered.fetch_add(1, Ordering::Relaxed);
        }
    }
}
