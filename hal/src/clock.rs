//! Time source for stamps: monotonic nanoseconds since an arbitrary origin, read from the host's
//! clock or from a simulated time that the run advances (`hitl run --clock sim`).
//!
//! The model is one clock type for both: [`MonotonicClock`] counts the host's monotonic time
//! from when it was made, or, made with [`MonotonicClock::simulated`], returns a [`SimTime`] that
//! only its owner moves (by whole loop periods). Everything that stamps (the tick, the report
//! reader, the cameras, the recorder's messages) reads the same clock, so a simulated run's
//! stamps are all simulated time.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// A monotonic clock in nanoseconds.
pub trait Clock {
    fn now_ns(&self) -> u64;
}

/// Simulated time in nanoseconds, shared by the clocks that read it and the one runtime that
/// advances it. It starts at 0 and never goes back.
#[derive(Debug, Clone, Default)]
pub struct SimTime(Arc<AtomicU64>);

impl SimTime {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn now_ns(&self) -> u64 {
        self.0.load(Ordering::Acquire)
    }

    /// Move time forward to `t_ns` (an earlier time leaves it where it is).
    pub fn advance_to(&self, t_ns: u64) {
        self.0.fetch_max(t_ns, Ordering::AcqRel);
    }
}

/// The run's clock: the host's monotonic clock counted from when this value was made, or a
/// simulated time ([`MonotonicClock::simulated`]).
#[derive(Debug, Clone)]
pub struct MonotonicClock {
    origin: Instant,
    sim: Option<SimTime>,
}

impl MonotonicClock {
    pub fn new() -> Self {
        Self { origin: Instant::now(), sim: None }
    }

    /// A clock that reads `time` instead of the host's clock.
    pub fn simulated(time: SimTime) -> Self {
        Self { origin: Instant::now(), sim: Some(time) }
    }

    /// The simulated time this clock reads, if it is simulated.
    pub fn sim_time(&self) -> Option<&SimTime> {
        self.sim.as_ref()
    }

    /// The instant this clock counts from (host time; meaningless for a simulated clock).
    pub fn origin(&self) -> Instant {
        self.origin
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        match &self.sim {
            Some(t) => t.now_ns(),
            None => u64::try_from(self.origin.elapsed().as_nanos()).unwrap_or(u64::MAX),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_simulated_clock_reads_only_the_time_it_is_given() {
        let time = SimTime::new();
        let clock = MonotonicClock::simulated(time.clone());
        assert_eq!(clock.now_ns(), 0);
        std::thread::sleep(std::time::Duration::from_millis(2));
        assert_eq!(clock.now_ns(), 0, "host time does not move it");
        time.advance_to(4_000_000);
        assert_eq!(clock.now_ns(), 4_000_000);
        time.advance_to(1_000);
        assert_eq!(clock.now_ns(), 4_000_000, "never backwards");
        assert!(clock.sim_time().is_some());
        assert!(MonotonicClock::new().sim_time().is_none());
    }
}
