//! The navigator's part in a simulated clock's lockstep (`hitl run --clock sim --closed-loop`,
//! docs/sim-clock.md).
//!
//! On the host's clock the navigator takes estimates as they come and looks at the loop's tick
//! every 10 ms: what it decides, and at which tick a correction starts, depends on how fast the
//! machine is. On a simulated clock it acts only in turns that the lockstep gives it while the
//! loop waits between two ticks: before simulated time moves on, the lockstep waits until every
//! estimate on its way to the navigator has reached it ([`EstimateFlow`]), then, when the
//! navigator has something to do (an estimate waiting, a capture's estimate overdue, the drill, the
//! return to the plan), hands it a turn and waits until the turn is done ([`NavigatorTurns`]). A
//! capture's estimate is thus used at the same tick in every run, and the correction it makes
//! starts at the same tick. The filter stays on the navigator's thread: the loop's thread only
//! hands the turn over and waits, outside the tick, allocating nothing.

use crate::telemetry::LoopStatus;
use crossbeam::channel::{Receiver, Sender};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Estimates on their way from the perception worker to the navigator, as the capture path's
/// forwarder counts them.
#[derive(Debug, Default)]
pub struct EstimateFlow {
    /// Results the forwarder has taken from the perception worker (counted after `teed`).
    forwarded: AtomicU64,
    /// Of those, the ones put on the navigator's channel.
    teed: AtomicU64,
}

impl EstimateFlow {
    /// One result taken from the worker; `teed` if it was put on the navigator's channel.
    pub fn count(&self, teed: bool) {
        if teed {
            self.teed.fetch_add(1, Ordering::Release);
        }
        self.forwarded.fetch_add(1, Ordering::Release);
    }

    /// Whether the forwarder has taken all `produced` results of the worker.
    pub fn forwarded_all(&self, produced: u64) -> bool {
        self.forwarded.load(Ordering::Acquire) >= produced
    }
}

/// The lockstep's side of the navigator: whether it needs a turn, the turn, its end.
pub struct NavigatorTurns {
    flow: Arc<EstimateFlow>,
    status: Arc<LoopStatus>,
    /// Results the navigator has handled.
    handled: AtomicU64,
    /// The first loop tick at which the navigator has something to do without a new estimate.
    next_due: AtomicU64,
    /// Turns asked, and turns done.
    asked: AtomicU64,
    done: AtomicU64,
    /// The navigator's thread has ended: no turn will be taken.
    ended: AtomicBool,
    ask: Sender<u64>,
}

/// The navigator's side: the turns it is given.
pub struct TurnTaker {
    pub turns: Arc<NavigatorTurns>,
    asks: Receiver<u64>,
}

impl NavigatorTurns {
    pub fn flow(&self) -> &EstimateFlow {
        &self.flow
    }

    /// Whether the navigator needs a turn now: an estimate waits for it, or something is due by
    /// the loop's tick.
    pub fn due(&self) -> bool {
        !self.ended.load(Ordering::Acquire)
            && (self.flow.teed.load(Ordering::Acquire) > self.handled.load(Ordering::Acquire)
                || self.status.tick.load(Ordering::Acquire)
                    >= self.next_due.load(Ordering::Acquire))
    }

    /// Give the navigator a turn; [`Self::taken`] says when it is over.
    pub fn give(&self) -> u64 {
        let turn = self.asked.fetch_add(1, Ordering::AcqRel) + 1;
        // The previous turn is over (the lockstep waited for it), so the slot is free.
        let _ = self.ask.try_send(turn);
        turn
    }

    /// The navigator's thread ends: no more turns.
    pub fn end(&self) {
        self.ended.store(true, Ordering::Release);
    }

    /// Whether `turn` is over (or the navigator has ended).
    pub fn taken(&self, turn: u64) -> bool {
        self.done.load(Ordering::Acquire) >= turn || self.ended.load(Ordering::Acquire)
    }
}

impl TurnTaker {
    /// Turns for a navigator fed through `flow`, at the ticks `status` reports.
    pub fn new(flow: Arc<EstimateFlow>, status: Arc<LoopStatus>) -> Self {
        let (ask, asks) = crossbeam::channel::bounded(1);
        let turns = Arc::new(NavigatorTurns {
            flow,
            status,
            handled: AtomicU64::new(0),
            // Due at once: the first turn also waits for the thread to have started.
            next_due: AtomicU64::new(0),
            asked: AtomicU64::new(0),
            done: AtomicU64::new(0),
            ended: AtomicBool::new(false),
            ask,
        });
        Self { turns, asks }
    }

    /// The next turn, if one is given within `timeout`.
    pub fn next(&self, timeout: Duration) -> Option<u64> {
        self.asks.recv_timeout(timeout).ok()
    }

    /// One estimate handled.
    pub fn handled(&self) {
        self.turns.handled.fetch_add(1, Ordering::AcqRel);
    }

    /// `turn` is over; the next one is due at `next_due` (a loop tick) unless an estimate comes.
    pub fn over(&self, turn: u64, next_due: u64) {
        self.turns.next_due.store(next_due, Ordering::Release);
        self.turns.done.store(turn, Ordering::Release);
    }
}

/// The longest the navigator waits, host time, for what a turn needs (the lockstep's own waits
/// give up after as long).
pub const GIVE_UP: Duration = Duration::from_secs(10);

/// Wait until `done`, at most `limit` of host time; whether it came.
pub fn wait_until(limit: Duration, done: impl Fn() -> bool) -> bool {
    let start = Instant::now();
    while !done() {
        if start.elapsed() > limit {
            return false;
        }
        std::thread::sleep(Duration::from_micros(100));
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turn_is_due_for_a_waiting_estimate_or_a_due_tick_and_over_when_the_navigator_says() {
        let flow = Arc::new(EstimateFlow::default());
        let status = Arc::new(LoopStatus::default());
        let taker = TurnTaker::new(Arc::clone(&flow), Arc::clone(&status));
        let turns = Arc::clone(&taker.turns);
        assert!(turns.due(), "the first turn is due at once");
        let t = turns.give();
        assert!(!turns.taken(t));
        assert_eq!(taker.next(Duration::from_millis(10)), Some(t));
        taker.over(t, 100);
        assert!(turns.taken(t));
        status.tick.store(99, Ordering::Release);
        assert!(!turns.due(), "nothing waits, nothing due before tick 100");
        flow.count(true);
        assert!(!flow.forwarded_all(2) && flow.forwarded_all(1));
        assert!(turns.due(), "an estimate waits");
        taker.handled();
        assert!(!turns.due());
        status.tick.store(100, Ordering::Release);
        assert!(turns.due(), "tick 100 is due");
        turns.end();
        assert!(!turns.due() && turns.taken(turns.give()), "an ended navigator is not waited on");
    }
}
