//! The worker never blocks the producer: a full queue drops the oldest frame and counts it;
//! results keep their frame's timestamp; the re-registration policy resets the backend.
#![allow(clippy::unwrap_used)]

use hitl_hal::Intrinsics;
use hitl_hal::Pose;
use hitl_perception::{
    spawn_worker, Estimate, EstimateKind, PerceptionError, PerceptionFrame, PoseEstimator,
    ReregisterPolicy,
};
use std::sync::atomic::Ordering;
use std::sync::mpsc as std_mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Blocks on its first frame until released; returns identity-free poses; counts resets.
struct Gated {
    started: std_mpsc::Sender<()>,
    release: Arc<Mutex<std_mpsc::Receiver<()>>>,
    first: bool,
    resets: Arc<Mutex<u32>>,
    lose_seq: Option<u64>,
}

impl PoseEstimator for Gated {
    fn name(&self) -> String {
        "gated".into()
    }
    fn estimate(&mut self, f: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
        if self.first {
            self.first = false;
            self.started.send(()).unwrap();
            self.release.lock().unwrap().recv().unwrap();
        }
        if Some(f.seq) == self.lose_seq {
            return Ok(Estimate::lost());
        }
        let p = Pose::translation(0.0, 0.0, f.seq as f64);
        Ok(Estimate { pose: Some(p), kind: EstimateKind::Tracked, residual_m: 0.0 })
    }
    fn reset(&mut self) {
        *self.resets.lock().unwrap() += 1;
    }
}

fn frame(seq: u64) -> PerceptionFrame {
    PerceptionFrame {
        timestamp_ns: 1000 + seq,
        seq,
        intrinsics: Intrinsics::pinhole(2, 1, 1.0, 1.0, 0.5, 0.0),
        color: vec![].into(),
        depth_m: vec![1.0, 1.0].into(),
        mask: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_queue_drops_the_oldest_and_counts_it() {
    let (started_tx, started_rx) = std_mpsc::channel();
    let (release_tx, release_rx) = std_mpsc::channel();
    let resets = Arc::new(Mutex::new(0));
    let est = Gated {
        started: started_tx,
        release: Arc::new(Mutex::new(release_rx)),
        first: true,
        resets: resets.clone(),
        lose_seq: Some(5),
    };
    let (h, mut rx, task) = spawn_worker(Box::new(est), 2, 16, ReregisterPolicy::default());
    h.push(frame(0));
    tokio::task::spawn_blocking(move || started_rx.recv_timeout(Duration::from_secs(10)).unwrap())
        .await
        .unwrap();
    // The backend is busy with frame 0: five more frames into a queue of two.
    let dropped: Vec<bool> = (1..=5).map(|s| h.push(frame(s))).collect();
    assert_eq!(dropped, vec![false, false, true, true, true]);
    assert_eq!(h.stats.dropped.load(Ordering::Relaxed), 3);
    assert_eq!(h.queue.len(), 2);
    release_tx.send(()).unwrap();
    h.close();
    let mut got = Vec::new();
    while let Some(r) = rx.recv().await {
        got.push(r);
    }
    task.await.unwrap();
    let seqs: Vec<u64> = got.iter().map(|r| r.seq).collect();
    assert_eq!(seqs, vec![0, 4, 5], "the newest frames survive, in order");
    for r in &got {
        assert_eq!(r.timestamp_ns, 1000 + r.seq);
    }
    let last = got[2].estimate.as_ref().unwrap();
    assert!(last.pose.is_none());
    assert_eq!(h.stats.lost.load(Ordering::Relaxed), 1);
    assert_eq!(*resets.lock().unwrap(), 1, "a lost frame resets the backend");
    assert_eq!(h.stats.pushed.load(Ordering::Relaxed), 6);
}

#[tokio::test(flavor = "current_thread")]
async fn periodic_reregistration_resets_every_n_frames() {
    let (started_tx, _started_rx) = std_mpsc::channel();
    let (release_tx, release_rx) = std_mpsc::channel();
    release_tx.send(()).unwrap();
    let resets = Arc::new(Mutex::new(0));
    let est = Gated {
        started: started_tx,
        release: Arc::new(Mutex::new(release_rx)),
        first: true,
        resets: resets.clone(),
        lose_seq: None,
    };
    let policy = ReregisterPolicy { every_n_frames: Some(3), max_residual_m: None };
    let (h, mut rx, task) = spawn_worker(Box::new(est), 16, 16, policy);
    for s in 0..7 {
        h.push(frame(s));
    }
    h.close();
    let mut n = 0;
    while let Some(r) = rx.recv().await {
        assert_eq!(r.seq, n);
        n += 1;
    }
    task.await.unwrap();
    assert_eq!(n, 7);
    // Before frames 3 and 6.
    assert_eq!(*resets.lock().unwrap(), 2);
    assert_eq!(h.stats.resets.load(Ordering::Relaxed), 2);
}
