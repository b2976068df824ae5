//! The bounded lock-free queues between the loop and the recorder, with their drop counters.
//!
//! Telemetry pushes never block or allocate: when a queue is full the oldest message is
//! dropped and counted. Frames go through their own small queue: a frame that cannot be queued
//! is counted and reported as a `capture-not-recorded` safety event, never dropped silently.

use crate::msg::{
    ArmStateMsg, ClosedLoopMsg, ClosedLoopTopic, EventKind, FrameRecord, LightMsg, PoseStamped,
    SafetyEventMsg, SetpointMsg, TfMsg, TimingMsg, TriggerFiredMsg,
};
use crossbeam_queue::ArrayQueue;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// How many messages each queue holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QueueCapacity {
    /// Each telemetry topic (setpoint, state, timing, light, tf, estimate).
    pub telemetry: usize,
    /// Safety events.
    pub events: usize,
    /// Frames (each holds its pixel buffers: keep small).
    pub frames: usize,
}

impl Default for QueueCapacity {
    fn default() -> Self {
        // 4096 messages are 16 s of a 250 Hz topic; 16 frames are about half a second at 30 fps.
        Self { telemetry: 4096, events: 1024, frames: 16 }
    }
}

/// Topics whose drops are counted (index into the counters).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Counted {
    Setpoint = 0,
    State = 1,
    Timing = 2,
    Light = 3,
    Event = 4,
    Tf = 5,
    Estimate = 6,
    Fired = 7,
    ClosedLoop = 8,
}

pub(crate) const COUNTED_TOPICS: [(Counted, &str); 9] = [
    (Counted::Setpoint, crate::topics::SETPOINT),
    (Counted::State, crate::topics::STATE),
    (Counted::Timing, crate::topics::TIMING),
    (Counted::Light, crate::topics::LIGHT),
    (Counted::Event, crate::topics::EVENT),
    (Counted::Tf, crate::topics::TF),
    (Counted::Estimate, crate::topics::POSE_ESTIMATE),
    (Counted::Fired, crate::topics::TRIGGER_FIRED),
    (Counted::ClosedLoop, "/closed_loop/*"),
];

pub(crate) struct Queues {
    pub setpoint: ArrayQueue<SetpointMsg>,
    pub state: ArrayQueue<ArmStateMsg>,
    pub timing: ArrayQueue<TimingMsg>,
    pub light: ArrayQueue<LightMsg>,
    pub event: ArrayQueue<SafetyEventMsg>,
    pub tf: ArrayQueue<TfMsg>,
    pub estimate: ArrayQueue<PoseStamped>,
    pub fired: ArrayQueue<TriggerFiredMsg>,
    pub frames: ArrayQueue<FrameRecord>,
    /// The closed loop's messages (from the navigator's thread, never the tick).
    pub closed_loop: ArrayQueue<ClosedLoopMsg>,
    pub drops: [AtomicU64; 9],
    pub frames_not_recorded: AtomicU64,
    /// Metadata records to write (from the session thread, never the tick): name and map.
    pub metadata: std::sync::Mutex<Vec<(String, std::collections::BTreeMap<String, String>)>>,
    /// Set by the recorder when it stops taking messages (finished): pushes become no-ops.
    pub closed: AtomicBool,
}

/// The loop's side of the recorder: cheap to clone (one `Arc`), safe to share between threads.
#[derive(Clone)]
pub struct Telemetry {
    pub(crate) q: Arc<Queues>,
}

impl std::fmt::Debug for Telemetry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Telemetry")
            .field("drops", &self.drops())
            .field("frames_not_recorded", &self.frames_not_recorded())
            .finish()
    }
}

impl Telemetry {
    pub(crate) fn new(cap: QueueCapacity) -> Self {
        let t = cap.telemetry.max(1);
        Self {
            q: Arc::new(Queues {
                setpoint: ArrayQueue::new(t),
                state: ArrayQueue::new(t),
                timing: ArrayQueue::new(t),
                light: ArrayQueue::new(t),
                event: ArrayQueue::new(cap.events.max(1)),
                tf: ArrayQueue::new(t),
                estimate: ArrayQueue::new(t),
                fired: ArrayQueue::new(t),
                frames: ArrayQueue::new(cap.frames.max(1)),
                closed_loop: ArrayQueue::new(t),
                drops: Default::default(),
                frames_not_recorded: AtomicU64::new(0),
                metadata: Default::default(),
                closed: AtomicBool::new(false),
            }),
        }
    }

    fn push_counted<T>(&self, q: &ArrayQueue<T>, which: Counted, m: T) {
        if q.force_push(m).is_some() {
            self.q.drops[which as usize].fetch_add(1, Ordering::Relaxed);
        }
    }

    /// A metadata record named `name` (e.g. the run's `approach_plan`), written with the next
    /// batch. Takes a lock and allocates: for the session thread, never the tick.
    pub fn push_metadata(&self, name: &str, map: std::collections::BTreeMap<String, String>) {
        if let Ok(mut pending) = self.q.metadata.lock() {
            pending.push((name.to_string(), map));
        }
    }

    /// `/arm/setpoint`. Never blocks or allocates (tick-safe).
    pub fn push_setpoint(&self, m: &SetpointMsg) {
        self.push_counted(&self.q.setpoint, Counted::Setpoint, *m);
    }

    /// `/arm/state`. Never blocks or allocates.
    pub fn push_state(&self, m: &ArmStateMsg) {
        self.push_counted(&self.q.state, Counted::State, *m);
    }

    /// `/loop/timing`. Never blocks or allocates (tick-safe).
    pub fn push_timing(&self, m: &TimingMsg) {
        self.push_counted(&self.q.timing, Counted::Timing, *m);
    }

    /// `/light/state`. Never blocks or allocates (tick-safe).
    pub fn push_light(&self, m: &LightMsg) {
        self.push_counted(&self.q.light, Counted::Light, *m);
    }

    /// `/trigger/fired`. Never blocks or allocates (tick-safe).
    pub fn push_fired(&self, m: &TriggerFiredMsg) {
        self.push_counted(&self.q.fired, Counted::Fired, *m);
    }

    /// `/safety/event`. Never blocks; allocates nothing for [`SafetyEventMsg::numeric`] events.
    pub fn push_event(&self, m: SafetyEventMsg) {
        self.push_counted(&self.q.event, Counted::Event, m);
    }

    /// `/tf` at any instant (frames carry their own transforms too). Never blocks or allocates.
    pub fn push_tf(&self, m: &TfMsg) {
        self.push_counted(&self.q.tf, Counted::Tf, *m);
    }

    /// `/pose/estimate` from the perception worker, stamped with the frame's capture time.
    pub fn push_pose_estimate(&self, m: &PoseStamped) {
        self.push_counted(&self.q.estimate, Counted::Estimate, *m);
    }

    /// One of the closed loop's `/closed_loop/*` messages (allocates: the navigator's thread,
    /// never the tick). Never blocks; drops the oldest when full.
    pub fn push_closed_loop(&self, topic: ClosedLoopTopic, t_ns: u64, value: serde_json::Value) {
        let m = ClosedLoopMsg { topic, t_ns, value };
        self.push_counted(&self.q.closed_loop, Counted::ClosedLoop, m);
    }

    /// Queue a capture for recording (camera intake, not the tick). Returns false when the
    /// frame could not be queued: it is then counted and a `capture-not-recorded` event is
    /// queued in its place.
    pub fn push_frame(&self, frame: FrameRecord) -> bool {
        let (tick, capture_ns) = (frame.tick, frame.capture_ns);
        if self.q.closed.load(Ordering::Acquire) || self.q.frames.push(frame).is_err() {
            self.q.frames_not_recorded.fetch_add(1, Ordering::Relaxed);
            self.push_event(SafetyEventMsg::numeric(
                capture_ns,
                EventKind::CaptureNotRecorded,
                tick,
                None,
                self.q.frames.len() as f64,
                self.q.frames.capacity() as f64,
            ));
            return false;
        }
        true
    }

    /// Whether a frame can be queued now (for producers that prefer to wait, e.g. benchmarks).
    pub fn frame_queue_has_room(&self) -> bool {
        !self.q.frames.is_full()
    }

    /// Telemetry dropped so far, per topic.
    pub fn drops(&self) -> Vec<(&'static str, u64)> {
        COUNTED_TOPICS
            .iter()
            .map(|(c, name)| (*name, self.q.drops[*c as usize].load(Ordering::Relaxed)))
            .collect()
    }

    /// Total telemetry messages dropped so far.
    pub fn total_drops(&self) -> u64 {
        self.q.drops.iter().map(|d| d.load(Ordering::Relaxed)).sum()
    }

    /// Captures that could not be queued for recording.
    pub fn frames_not_recorded(&self) -> u64 {
        self.q.frames_not_recorded.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{EventDetail, Phase};
    use hitl_hal::Intrinsics;

    fn sp(tick: u64) -> SetpointMsg {
        SetpointMsg {
            tick,
            t_ns: tick,
            phase: Phase::Playback,
            q: [0.0; hitl_hal::DOF],
            qd: [0.0; hitl_hal::DOF],
        }
    }

    fn frame(tick: u64) -> FrameRecord {
        FrameRecord {
            tick,
            capture_ns: 1000 + tick,
            intrinsics: Intrinsics {
                width: 1,
                height: 1,
                fx: 1.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
                distortion: Default::default(),
            },
            color: None,
            depth: None,
            mask: None,
            gt_pose: None,
            tf: None,
            trigger_ns: None,
            light_level: None,
        }
    }

    #[test]
    fn full_telemetry_queue_drops_the_oldest_and_counts() {
        let t = Telemetry::new(QueueCapacity { telemetry: 4, events: 4, frames: 1 });
        for k in 0..6 {
            t.push_setpoint(&sp(k));
        }
        assert_eq!(t.total_drops(), 2);
        assert_eq!(t.drops()[0], (crate::topics::SETPOINT, 2));
        let kept: Vec<u64> = std::iter::from_fn(|| t.q.setpoint.pop().map(|m| m.tick)).collect();
        assert_eq!(kept, vec![2, 3, 4, 5]);
    }

    #[test]
    fn a_frame_that_cannot_be_queued_becomes_an_event() {
        let t = Telemetry::new(QueueCapacity { telemetry: 4, events: 4, frames: 1 });
        assert!(t.push_frame(frame(1)));
        assert!(!t.frame_queue_has_room());
        assert!(!t.push_frame(frame(2)));
        assert_eq!(t.frames_not_recorded(), 1);
        let ev = t.q.event.pop().expect("event");
        assert_eq!(ev.kind, EventKind::CaptureNotRecorded);
        assert_eq!(ev.t_ns, 1002);
        assert!(matches!(ev.detail, EventDetail::Numeric { tick: 2, .. }));
        assert_eq!(t.q.frames.pop().map(|f| f.tick), Some(1));
    }
}
