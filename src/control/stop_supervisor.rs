//! The stop supervisor: after a tripped run, off the loop thread, make sure the control box has
//! really stopped.
//!
//! The tick's hold only *sends* a stop (a non-waiting write: the tick never waits for the box).
//! A stop that is lost (a reply never comes, the box is busy, a packet is dropped on a stalled
//! link) would leave the arm in servo mode with nobody streaming to it. So once the loop has
//! ended, the session repeats the box's stop (set_state(4)) every [`StopPolicy::repeat`] until a
//! report *received after the first repeat* shows state 4, and gives up after
//! [`StopPolicy::give_up`], as the official SDK does for its emergency stop (100 ms, 3 s). The
//! result, confirmed or not, goes into the run report and the recording's final
//! `/safety/event`. See docs/safety.md.

use hitl_hal::{Arm, ArmState, Clock};
use std::time::Duration;

/// The box's stopped state, as reports show it.
pub const STATE_STOPPED: u8 = 4;

/// How often and how long the stop is repeated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopPolicy {
    /// Between two stop requests. Default 100 ms (the SDK's).
    pub repeat: Duration,
    /// Give up when no report shows the stop after this long. Default 3 s (the SDK's).
    pub give_up: Duration,
    /// How often the reports are looked at between requests. Default 2 ms.
    pub poll: Duration,
}

impl Default for StopPolicy {
    fn default() -> Self {
        Self {
            repeat: Duration::from_millis(100),
            give_up: Duration::from_secs(3),
            poll: Duration::from_millis(2),
        }
    }
}

/// What the supervisor saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StopConfirmation {
    /// A report received after the first request showed state 4.
    pub confirmed: bool,
    /// Stop requests sent (including those whose write failed).
    pub requests: u32,
    /// Requests whose write failed (the connection is gone, for instance).
    pub send_errors: u32,
    /// From the first request to the confirming report (or to giving up), nanoseconds.
    pub waited_ns: u64,
    /// The state the last fresh report showed, if any report came after the first request.
    pub last_state: Option<u8>,
}

impl StopConfirmation {
    /// One line for the operator and the recording.
    pub fn describe(&self) -> String {
        let waited = self.waited_ns as f64 / 1e9;
        if self.confirmed {
            format!(
                "box stop confirmed: a report showed state 4 {waited:.3} s after the first of {} \
                 stop request(s)",
                self.requests
            )
        } else {
            let seen = match self.last_state {
                Some(s) => format!("the last report showed state {s}"),
                None => "no report arrived".to_string(),
            };
            let failed = if self.send_errors > 0 {
                format!(", {} of them could not be sent", self.send_errors)
            } else {
                String::new()
            };
            format!(
                "box stop NOT confirmed: {seen} within {waited:.3} s of {} stop request(s){failed}; \
                 check the arm and use its emergency stop if it moves",
                self.requests
            )
        }
    }
}

/// Repeat the arm's stop until a fresh report shows state 4, or `policy.give_up` passes.
///
/// `latest_report` returns the newest report the reader has (stale or not); only reports
/// received (per `clock`) at or after the first request count, so a report from before the stop
/// cannot confirm it. Runs on the session thread after the loop; blocks at most about
/// `policy.give_up` plus one `policy.poll`.
pub fn supervise_stop<A: Arm + ?Sized>(
    arm: &mut A,
    latest_report: &mut dyn FnMut() -> Option<ArmState>,
    clock: &dyn Clock,
    policy: StopPolicy,
) -> StopConfirmation {
    let start = clock.now_ns();
    let repeat_ns = policy.repeat.as_nanos() as u64;
    let give_up_ns = policy.give_up.as_nanos() as u64;
    let mut result = StopConfirmation::default();
    let mut next_request = start;
    loop {
        let now = clock.now_ns();
        if let Some(report) = latest_report() {
            if report.received_ns >= start {
                result.last_state = Some(report.state);
                if report.state == STATE_STOPPED {
                    result.confirmed = true;
                    result.waited_ns = report.received_ns - start;
                    return result;
                }
            }
        }
        if now.saturating_sub(start) >= give_up_ns {
            result.waited_ns = now - start;
            return result;
        }
        if now >= next_request {
            result.requests += 1;
            if arm.stop().is_err() {
                result.send_errors += 1;
            }
            next_request += repeat_ns.max(1);
        }
        std::thread::sleep(policy.poll);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_hal::{ErrorKind, ErrorType, Joints, MonotonicClock, SimTime};
    use std::cell::Cell;
    use std::rc::Rc;

    type Failed = ErrorKind;

    /// An arm that counts stop requests; each fails when `fail`.
    struct Box4 {
        stops: Rc<Cell<u32>>,
        fail: bool,
    }
    impl ErrorType for Box4 {
        type Error = Failed;
    }
    impl Arm for Box4 {
        fn enable_servo(&mut self) -> Result<(), Failed> {
            Ok(())
        }
        fn servo_joint(&mut self, _: &Joints) -> Result<(), Failed> {
            Ok(())
        }
        fn stop(&mut self) -> Result<(), Failed> {
            self.stops.set(self.stops.get() + 1);
            if self.fail {
                Err(ErrorKind::Disconnected)
            } else {
                Ok(())
            }
        }
        fn joint_positions(&mut self) -> Result<Joints, Failed> {
            Ok([0.0; hitl_hal::DOF])
        }
        fn codes(&mut self) -> Result<(u8, u8), Failed> {
            Ok((0, 0))
        }
    }

    fn state(received_ns: u64, state: u8) -> ArmState {
        ArmState { received_ns, state, ..ArmState::default() }
    }

    fn fast() -> StopPolicy {
        StopPolicy {
            repeat: Duration::from_millis(10),
            give_up: Duration::from_millis(300),
            poll: Duration::from_millis(1),
        }
    }

    /// A simulated clock, started at 1 ms, that `latest` moves on by one poll (1 ms) each time it
    /// is asked, so the schedule is the same however the machine is loaded.
    fn stepped() -> (MonotonicClock, impl Fn() -> u64) {
        let time = SimTime::new();
        time.advance_to(1_000_000);
        let clock = MonotonicClock::simulated(time.clone());
        (clock, move || {
            let t = time.now_ns() + 1_000_000;
            time.advance_to(t);
            t
        })
    }

    #[test]
    fn repeats_until_a_fresh_report_shows_the_stop() {
        let (clock, tick) = stepped();
        let stops = Rc::new(Cell::new(0));
        let mut arm = Box4 { stops: Rc::clone(&stops), fail: false };
        // A stale report already says 4: it must not count. The box stops on the third request
        // (sent 20 ms after the start); the next report, 2 ms later (one poll each), confirms.
        let seen = Rc::clone(&stops);
        let mut latest = move || {
            let now = tick();
            Some(if seen.get() >= 3 { state(now, 4) } else { state(0, 4) })
        };
        let r = supervise_stop(&mut arm, &mut latest, &clock, fast());
        assert!(r.confirmed, "{r:?}");
        assert_eq!(r.requests, 3);
        assert_eq!(r.last_state, Some(4));
        assert_eq!(r.waited_ns, 22_000_000, "{r:?}");
        assert!(r.describe().contains("confirmed"), "{}", r.describe());
    }

    #[test]
    fn gives_up_and_says_so() {
        let (clock, tick) = stepped();
        let stops = Rc::new(Cell::new(0));
        let mut arm = Box4 { stops: Rc::clone(&stops), fail: true };
        let mut latest = move || Some(state(tick(), 1));
        let r = supervise_stop(&mut arm, &mut latest, &clock, fast());
        assert!(!r.confirmed);
        assert_eq!(r.waited_ns, 300_000_000, "{r:?}");
        // One request every 10 ms for 300 ms: at 0, 10, ..., 290 ms.
        assert_eq!(r.requests, 30, "{r:?}");
        assert_eq!(stops.get(), 30);
        assert_eq!(r.send_errors, r.requests);
        assert_eq!(r.last_state, Some(1));
        let d = r.describe();
        assert!(d.contains("NOT confirmed") && d.contains("state 1"), "{d}");
    }
}
