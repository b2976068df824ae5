//! The closed loop's correction stage: the one thing the tick does for `--closed-loop`. It adds
//! the joint offset of the current correction segment to the planned setpoint of the playback
//! (and of the settle after it), and nothing else.
//!
//! A [`CorrectionSegment`] is prepared off the loop thread by the navigator
//! (`crate::closed_loop`): the offsets (position, velocity, acceleration) for a run of ticks,
//! sampled from Ruckig moves, that start from the offset in effect at its first tick and end back
//! at zero; before it is handed over, every corrected setpoint it makes (plan plus offset) has
//! passed the preflight's rules and the corridor. The stage takes a segment only at its first
//! tick, and only when it was built on the segment in effect then (so the offset never jumps);
//! otherwise it gives it back unused and counts it. Past a segment's end the offset is zero: the
//! plan itself. Buffers go back to the navigator through a queue, so the tick neither allocates
//! nor frees; the tick reports each switch (tick, segment id) so the navigator knows which
//! offset each capture was taken with.

use crossbeam::queue::ArrayQueue;
use hitl_hal::{JointState, Phase, DOF};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The joint offsets of a correction for a run of ticks, starting at `from_tick`.
#[derive(Debug)]
pub struct CorrectionSegment {
    /// Never 0 (0 names "no segment": the plan itself).
    pub id: u64,
    /// The segment whose offset at `from_tick` this one starts from (0: none, a zero offset).
    pub based_on: u64,
    /// Loop tick of sample 0.
    pub from_tick: u64,
    samples: Box<[JointState]>,
    len: usize,
}

impl CorrectionSegment {
    /// An empty segment with room for `capacity` ticks (allocates: off the loop).
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            id: 0,
            based_on: 0,
            from_tick: 0,
            samples: vec![JointState::default(); capacity.max(1)].into_boxed_slice(),
            len: 0,
        }
    }

    /// Room, in ticks.
    pub fn capacity(&self) -> usize {
        self.samples.len()
    }

    /// Fill with `samples` from `from_tick`; false (and unchanged) when they do not fit.
    pub fn fill(&mut self, id: u64, based_on: u64, from_tick: u64, samples: &[JointState]) -> bool {
        if samples.len() > self.samples.len() || id == 0 {
            return false;
        }
        self.samples[..samples.len()].copy_from_slice(samples);
        (self.id, self.based_on, self.from_tick, self.len) =
            (id, based_on, from_tick, samples.len());
        true
    }

    /// The offset at loop tick `k`: zero before the segment and after its end.
    pub fn at(&self, k: u64) -> JointState {
        k.checked_sub(self.from_tick)
            .and_then(|i| usize::try_from(i).ok())
            .and_then(|i| self.samples[..self.len].get(i).copied())
            .unwrap_or_default()
    }

    /// The first tick after the segment.
    pub fn end_tick(&self) -> u64 {
        self.from_tick + self.len as u64
    }

    pub fn samples(&self) -> &[JointState] {
        &self.samples[..self.len]
    }
}

/// A segment taking effect: from `tick` on, segment `id`'s offsets apply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Switch {
    pub tick: u64,
    pub id: u64,
}

/// Counters of the stage, readable from any thread.
#[derive(Debug, Default)]
pub struct CorrectionStats {
    /// The id of the segment in effect (0: none yet).
    pub active: AtomicU64,
    /// Segments taken.
    pub taken: AtomicU64,
    /// Segments given back unused: late (their first tick had passed) or built on another.
    pub refused: AtomicU64,
}

/// The queues between the navigator and the stage.
#[derive(Debug, Clone)]
pub struct CorrectionQueues {
    pub incoming: Arc<ArrayQueue<CorrectionSegment>>,
    pub spent: Arc<ArrayQueue<CorrectionSegment>>,
    pub switches: Arc<ArrayQueue<Switch>>,
    pub stats: Arc<CorrectionStats>,
}

impl CorrectionQueues {
    /// Queues for `buffers` segment buffers in circulation.
    pub fn new(buffers: usize) -> Self {
        Self {
            incoming: Arc::new(ArrayQueue::new(1)),
            // Every buffer can be in `spent` at once, so giving one back never displaces another.
            spent: Arc::new(ArrayQueue::new(buffers.max(1) + 2)),
            switches: Arc::new(ArrayQueue::new(256)),
            stats: Arc::new(CorrectionStats::default()),
        }
    }
}

/// The tick's side. `open_loop()` does nothing.
#[derive(Debug, Default)]
pub struct CorrectionStage {
    link: Option<StageLink>,
}

#[derive(Debug)]
struct StageLink {
    queues: CorrectionQueues,
    current: Option<CorrectionSegment>,
    pending: Option<CorrectionSegment>,
}

impl CorrectionStage {
    /// No correction: every setpoint is the plan's.
    pub fn open_loop() -> Self {
        Self { link: None }
    }

    /// The closed loop's stage, fed by a navigator through `queues`.
    pub fn closed_loop(queues: CorrectionQueues) -> Self {
        Self { link: Some(StageLink { queues, current: None, pending: None }) }
    }

    /// The setpoint tick `k` sends in `phase`: `planned` plus the offset in effect during the
    /// playback and the settle after it; `planned` itself otherwise (approach, stop, retreat).
    /// Never allocates, frees or blocks.
    pub fn apply(&mut self, k: u64, phase: Phase, planned: JointState) -> JointState {
        let Some(link) = self.link.as_mut() else { return planned };
        link.take_incoming(k);
        link.switch_at(k);
        let corrects =
            matches!(phase, Phase::LeadIn | Phase::Playback | Phase::LeadOut | Phase::Settle);
        let Some(seg) = link.current.as_ref().filter(|_| corrects) else { return planned };
        let off = seg.at(k);
        let mut out = planned;
        for j in 0..DOF {
            out.q[j] += off.q[j];
            out.qd[j] += off.qd[j];
            out.qdd[j] += off.qdd[j];
        }
        out
    }
}

impl StageLink {
    fn give_back(&self, seg: CorrectionSegment, refused: bool) {
        if refused {
            self.queues.stats.refused.fetch_add(1, Ordering::Relaxed);
        }
        // Never displaces (room for every buffer); if it ever did, the displaced one is freed.
        let _ = self.queues.spent.force_push(seg);
    }

    fn take_incoming(&mut self, k: u64) {
        while let Some(seg) = self.queues.incoming.pop() {
            if seg.from_tick <= k {
                self.give_back(seg, true);
                continue;
            }
            if let Some(older) = self.pending.replace(seg) {
                self.give_back(older, true);
            }
        }
    }

    fn switch_at(&mut self, k: u64) {
        if self.pending.as_ref().is_none_or(|p| p.from_tick > k) {
            return;
        }
        let Some(next) = self.pending.take() else { return };
        let in_effect = self.current.as_ref().map_or(0, |c| c.id);
        if next.based_on != in_effect {
            self.give_back(next, true);
            return;
        }
        let id = next.id;
        if let Some(old) = self.current.replace(next) {
            self.give_back(old, false);
        }
        let _ = self.queues.switches.force_push(Switch { tick: k, id });
        self.queues.stats.active.store(id, Ordering::Relaxed);
        self.queues.stats.taken.fetch_add(1, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(value: f64, n: usize) -> Vec<JointState> {
        (0..n).map(|i| JointState::rest([value * i as f64 / n as f64; DOF])).collect()
    }

    fn segment(id: u64, based_on: u64, from: u64, samples: &[JointState]) -> CorrectionSegment {
        let mut s = CorrectionSegment::with_capacity(16);
        assert!(s.fill(id, based_on, from, samples));
        s
    }

    #[test]
    fn offsets_apply_from_the_first_tick_in_the_playback_only() {
        let q = CorrectionQueues::new(2);
        let mut stage = CorrectionStage::closed_loop(q.clone());
        let plan = JointState::rest([1.0; DOF]);
        q.incoming.push(segment(1, 0, 10, &ramp(0.01, 5))).expect("room");
        assert_eq!(stage.apply(9, Phase::Playback, plan), plan, "before its first tick");
        assert_eq!(stage.apply(10, Phase::Playback, plan).q[0], 1.0, "sample 0: the base's offset");
        assert!((stage.apply(12, Phase::Playback, plan).q[0] - 1.004).abs() < 1e-12);
        assert_eq!(stage.apply(12, Phase::Retreat, plan), plan, "never in the retreat");
        assert_eq!(stage.apply(15, Phase::Playback, plan), plan, "zero after its end");
        assert_eq!(q.switches.pop(), Some(Switch { tick: 10, id: 1 }));
        assert_eq!(q.stats.active.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn late_or_mismatched_segments_go_back_unused() {
        let q = CorrectionQueues::new(3);
        let mut stage = CorrectionStage::closed_loop(q.clone());
        let plan = JointState::rest([0.0; DOF]);
        q.incoming.push(segment(1, 0, 5, &ramp(0.01, 4))).expect("room");
        stage.apply(6, Phase::Playback, plan);
        assert_eq!(q.stats.refused.load(Ordering::Relaxed), 1, "late");
        assert_eq!(q.spent.len(), 1);
        q.incoming.push(segment(2, 7, 8, &ramp(0.01, 4))).expect("room");
        stage.apply(7, Phase::Playback, plan);
        assert_eq!(stage.apply(8, Phase::Playback, plan), plan, "built on another: refused");
        assert_eq!(q.stats.refused.load(Ordering::Relaxed), 2);
        assert!(q.switches.pop().is_none());
        assert_eq!(CorrectionStage::open_loop().apply(8, Phase::Playback, plan), plan);
    }
}
