//! The loop's pace on a simulated clock (`hitl run --clock sim`): instead of sleeping until the
//! next deadline, [`Lockstep`] moves the simulated time to it and lets the simulated world catch
//! up to that time before the tick runs.
//!
//! The world is whatever the run simulates (the embedded stub's physics, reports, camera): the
//! session hands a [`World`] that advances it to a time and returns once everything due by then
//! has happened and been heard (the arm's report for that time read, the frames of earlier
//! captures rendered and estimated). The tick then runs exactly as on the host's clock: same
//! code, same stamps read from the run's clock, which now reads simulated time. Time moves by
//! whole periods, so tick `k` is at `k * period` and every wake-up is punctual: lateness and
//! overruns cannot be measured on this pace (docs/safety.md).

use super::period::{Pace, Wake};
use hitl_hal::SimTime;

/// The simulated world the loop runs against.
pub trait World {
    /// Bring everything the run simulates to `t_ns` (simulated time has been moved there).
    fn advance_to(&mut self, t_ns: u64);
}

impl<F: FnMut(u64)> World for F {
    fn advance_to(&mut self, t_ns: u64) {
        self(t_ns)
    }
}

/// Whole periods of simulated time, one per tick.
pub struct Lockstep<W> {
    time: SimTime,
    period_ns: u64,
    start_ns: u64,
    tick: u64,
    world: W,
}

impl<W: World> Lockstep<W> {
    /// Ticks from the simulated time's present, one `period_ns` apart; the first is one period
    /// on (as [`super::Periodic`]'s).
    pub fn new(time: SimTime, period_ns: u64, world: W) -> Self {
        let start_ns = time.now_ns();
        Self { time, period_ns: period_ns.max(1), start_ns, tick: 0, world }
    }

    /// The world, back (for what follows the loop on the same simulated time).
    pub fn into_world(self) -> W {
        self.world
    }
}

impl<W: World> Pace for Lockstep<W> {
    fn wait(&mut self) -> Wake {
        self.tick += 1;
        let deadline = self.start_ns + self.tick * self.period_ns;
        self.time.advance_to(deadline);
        {
            let _not_the_tick = super::probe::leave_rt_loop();
            self.world.advance_to(deadline);
        }
        Wake { tick: self.tick - 1, deadline_ns: deadline, late_ns: 0, overrun: false }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_wait_moves_time_one_period_and_lets_the_world_catch_up() {
        let time = SimTime::new();
        time.advance_to(1_000);
        let mut seen = Vec::new();
        let mut pace = Lockstep::new(time.clone(), 4_000_000, |t: u64| seen.push(t));
        let w = pace.wait();
        assert_eq!((w.tick, w.deadline_ns, w.late_ns, w.overrun), (0, 4_001_000, 0, false));
        assert_eq!(time.now_ns(), 4_001_000);
        let w = pace.wait();
        assert_eq!((w.tick, w.deadline_ns), (1, 8_001_000));
        drop(pace);
        assert_eq!(seen, vec![4_001_000, 8_001_000]);
    }
}
