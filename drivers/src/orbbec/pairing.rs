//! Pairing framesets with the capture requests (triggers) that caused them, by timestamps, not by
//! order: a frame stamped before a trigger fired is not that trigger's frame.
//!
//! With exposure stamps (the SDK's global timestamps) a frame belongs to the newest pending
//! trigger fired at or before its exposure (within `slack_ns`, the clock fit's error); older
//! pending triggers got no frame and are missed. With arrival stamps (the host's receive time,
//! later than the exposure by the transfer) a frame belongs to the oldest pending trigger fired
//! before it arrived; triggers pending longer than the frame timeout are missed by
//! [`Pairing::expire`]. A frame older than every pending trigger is stale and dropped.

use std::collections::VecDeque;

use hitl_hal::CaptureRequest;

/// What became of one frameset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Paired {
    /// The frame answers `request`; `missed` older triggers got no frame.
    Frame { request: CaptureRequest, missed: u32 },
    /// Older than every pending trigger (or nothing pending): not a frame we asked for.
    Stale,
}

/// Triggers waiting for their frames, oldest first.
#[derive(Debug)]
pub struct Pairing {
    pending: VecDeque<CaptureRequest>,
    capacity: usize,
    slack_ns: u64,
}

impl Pairing {
    pub fn new(capacity: usize, slack_ns: u64) -> Self {
        let capacity = capacity.max(1);
        Self { pending: VecDeque::with_capacity(capacity), capacity, slack_ns }
    }

    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// A trigger was fired. When full, the oldest pending trigger is given up (returned).
    pub fn push(&mut self, request: CaptureRequest) -> Option<CaptureRequest> {
        let evicted =
            if self.pending.len() >= self.capacity { self.pending.pop_front() } else { None };
        self.pending.push_back(request);
        evicted
    }

    /// Give up triggers fired more than `timeout_ns` before `now_ns`; returns how many.
    pub fn expire(&mut self, now_ns: u64, timeout_ns: u64) -> u32 {
        let mut n = 0;
        while self.pending.front().is_some_and(|r| now_ns.saturating_sub(r.fired_ns) > timeout_ns) {
            self.pending.pop_front();
            n += 1;
        }
        n
    }

    /// Pair a frame stamped `stamp_ns` (host clock) with its trigger.
    pub fn pair(&mut self, stamp_ns: u64, exposure_stamp: bool) -> Paired {
        let latest = stamp_ns.saturating_add(self.slack_ns);
        let idx = if exposure_stamp {
            self.pending.iter().rposition(|r| r.fired_ns <= latest)
        } else {
            self.pending.front().filter(|r| r.fired_ns <= latest).map(|_| 0)
        };
        let Some(idx) = idx else { return Paired::Stale };
        let missed = u32::try_from(idx).unwrap_or(u32::MAX);
        self.pending.drain(..idx);
        match self.pending.pop_front() {
            Some(request) => Paired::Frame { request, missed },
            None => Paired::Stale,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever the order of triggers and frames: a frame is never paired with a trigger fired
        /// after it (beyond the slack), each trigger is answered at most once, and every trigger
        /// ends up answered, missed or still pending.
        #[test]
        fn never_a_frame_before_its_trigger(
            events in proptest::collection::vec((any::<bool>(), 0u64..1_000, any::<bool>()), 1..60),
            slack in 0u64..20,
        ) {
            let mut p = Pairing::new(4, slack);
            let (mut t, mut fired, mut answered, mut missed) = (0u64, 0u32, Vec::new(), 0u32);
            for (is_trigger, dt, exposure) in events {
                t += dt;
                if is_trigger {
                    fired += 1;
                    if p.push(r(u64::from(fired), t)).is_some() {
                        missed += 1;
                    }
                } else {
                    let stamp = t.saturating_sub(dt / 2);
                    if let Paired::Frame { request, missed: m } = p.pair(stamp, exposure) {
                        prop_assert!(request.fired_ns <= stamp + slack);
                        prop_assert!(!answered.contains(&request.tick));
                        answered.push(request.tick);
                        missed += m;
                    }
                }
            }
            prop_assert_eq!(answered.len() as u32 + missed + p.pending() as u32, fired);
        }
    }

    fn r(tick: u64, fired_ns: u64) -> CaptureRequest {
        CaptureRequest { tick, fired_ns }
    }

    #[test]
    fn exposure_stamps_pair_with_the_newest_trigger_before_them() {
        let mut p = Pairing::new(8, 1_000);
        p.push(r(1, 100_000));
        p.push(r(2, 200_000));
        p.push(r(3, 300_000));
        // Exposed at 205 us: trigger 2's frame; trigger 1 got none.
        assert_eq!(p.pair(205_000, true), Paired::Frame { request: r(2, 200_000), missed: 1 });
        // A frame from before trigger 3 (a late frame of 2's exposure): stale, 3 still waits.
        assert_eq!(p.pair(250_000, true), Paired::Stale);
        assert_eq!(p.pending(), 1);
        // Within the slack of the clock fit: still trigger 3's.
        assert_eq!(p.pair(299_500, true), Paired::Frame { request: r(3, 300_000), missed: 0 });
        assert_eq!(p.pair(400_000, true), Paired::Stale);
    }

    #[test]
    fn arrival_stamps_pair_in_order_but_never_before_the_trigger() {
        let mut p = Pairing::new(8, 0);
        p.push(r(1, 100));
        p.push(r(2, 200));
        assert_eq!(p.pair(50, false), Paired::Stale);
        // Arrived after both fired: the oldest is the one whose exposure came first.
        assert_eq!(p.pair(250, false), Paired::Frame { request: r(1, 100), missed: 0 });
        assert_eq!(p.pair(260, false), Paired::Frame { request: r(2, 200), missed: 0 });
    }

    #[test]
    fn old_triggers_expire_and_a_full_queue_gives_up_the_oldest() {
        let mut p = Pairing::new(2, 0);
        assert_eq!(p.push(r(1, 100)), None);
        assert_eq!(p.push(r(2, 200)), None);
        assert_eq!(p.push(r(3, 300)), Some(r(1, 100)));
        assert_eq!(p.expire(1_250, 1_000), 1);
        assert_eq!(p.pending(), 1);
        assert_eq!(p.expire(1_250, 1_000), 0);
    }
}
