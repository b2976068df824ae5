//! A fixed period kept against absolute deadlines: deadline k is `start + k * period`, so a late
//! wake-up never shifts the ones after it (no drift). Optional sleep-then-spin for tight jitter.
//!
//! [`Pace`] is what the loop waits on between ticks: [`Periodic`] on the host's clock, or
//! [`super::lockstep::Lockstep`] on a simulated one.

use super::os;
use std::time::Duration;

/// How one wake-up went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Wake {
    /// Tick index, from 0.
    pub tick: u64,
    /// The deadline this wake-up was for (monotonic ns).
    pub deadline_ns: u64,
    /// How late the thread woke, ns.
    pub late_ns: u64,
    /// The previous tick's work ran past this deadline.
    pub overrun: bool,
}

/// What the loop waits on before each tick: the next deadline, and how punctual it was.
pub trait Pace {
    fn wait(&mut self) -> Wake;
}

/// The period clock of the real-time thread.
#[derive(Debug)]
pub struct Periodic {
    start_ns: u64,
    period_ns: u64,
    spin_ns: u64,
    tick: u64,
}

impl Periodic {
    /// Start counting now; the first deadline is one period from now.
    pub fn new(period: Duration, spin: Duration) -> Self {
        Self {
            start_ns: os::monotonic_ns(),
            period_ns: period.as_nanos().max(1) as u64,
            spin_ns: spin.as_nanos() as u64,
            tick: 0,
        }
    }

    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }
}

impl Pace for Periodic {
    /// Wait for the next deadline and say how punctual the wake-up was.
    ///
    /// When the thread comes back after a deadline has passed (its previous tick ran long, or the
    /// OS did not run it), the tick runs at once, marked `overrun`; every deadline missed that way
    /// runs back to back, so tick `k` always stands for `start + k * period`: playback time never
    /// slips behind wall time and no scheduled capture is skipped.
    fn wait(&mut self) -> Wake {
        self.tick += 1;
        let deadline = self.start_ns + self.tick * self.period_ns;
        let before = os::monotonic_ns();
        let overrun = before > deadline;
        if !overrun {
            if self.spin_ns > 0 {
                if deadline.saturating_sub(self.spin_ns) > before {
                    os::sleep_until_ns(deadline - self.spin_ns);
                }
                while os::monotonic_ns() < deadline {
                    std::hint::spin_loop();
                }
            } else {
                os::sleep_until_ns(deadline);
            }
        }
        let woke = os::monotonic_ns();
        Wake {
            tick: self.tick - 1,
            deadline_ns: deadline,
            late_ns: woke.saturating_sub(deadline),
            overrun,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deadlines_are_absolute_multiples_of_the_period() {
        let mut p = Periodic::new(Duration::from_millis(2), Duration::ZERO);
        let start = p.start_ns;
        let mut last = Wake::default();
        for _ in 0..5 {
            last = p.wait();
        }
        assert_eq!(last.tick, 4);
        assert_eq!(last.deadline_ns, start + 5 * 2_000_000);
        assert!(os::monotonic_ns() >= last.deadline_ns);
    }

    #[test]
    fn an_overrun_is_flagged_and_does_not_shift_the_schedule() {
        let mut p = Periodic::new(Duration::from_millis(2), Duration::ZERO);
        let start = p.start_ns;
        p.wait();
        std::thread::sleep(Duration::from_millis(5));
        let w = p.wait();
        assert!(w.overrun);
        assert_eq!(w.deadline_ns, start + 2 * 2_000_000);
        let w = p.wait();
        assert_eq!(w.deadline_ns, start + 3 * 2_000_000);
    }
}
