//! The stop planner: a thread that turns a trip into a sampled Ruckig stop, so the tick never
//! plans, allocates or waits.
//!
//! On a trip the tick pushes the state it last commanded into a lock-free queue and unparks the
//! planner; until the plan is back (typically well under one period) the tick bridges by
//! extrapolating that state. The plan's sample `i` is the setpoint for tick `from_tick + 1 + i`.
//! The planner's buffer is allocated when the planner starts, before the loop.

use super::motion::{plan_stop, MoveLimits};
use crossbeam::queue::ArrayQueue;
use hitl_hal::JointState;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::{self, JoinHandle, Thread};
use std::time::Duration;

/// What the tick asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopRequest {
    /// The last setpoint sent before the trip.
    pub from: JointState,
    /// The tick that setpoint was sent on.
    pub from_tick: u64,
}

/// A planned stop, sampled at the control period.
#[derive(Debug)]
pub struct StopPlan {
    pub from_tick: u64,
    samples: Box<[JointState]>,
    len: usize,
}

impl StopPlan {
    /// The setpoint for `tick`, or `None` once the stop is complete. `None` also for an empty
    /// plan (Ruckig refused), in which case the tick holds.
    pub fn at(&self, tick: u64) -> Option<&JointState> {
        let i = tick.checked_sub(self.from_tick + 1)?;
        self.samples[..self.len].get(usize::try_from(i).ok()?)
    }

    /// Where the stop ends, when there is a plan.
    pub fn last(&self) -> Option<&JointState> {
        self.samples[..self.len].last()
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn len(&self) -> usize {
        self.len
    }
}

/// The tick's side: request a stop, pick up the plan. Never blocks or allocates.
pub struct StopRequester {
    /// Requests made and plans made, counted (a simulated clock waits until they match).
    counts: Arc<(AtomicU64, AtomicU64)>,
    requests: Arc<ArrayQueue<StopRequest>>,
    plans: Arc<ArrayQueue<StopPlan>>,
    planner: Thread,
}

impl StopRequester {
    pub fn request(&self, request: StopRequest) {
        self.counts.0.fetch_add(1, Ordering::AcqRel);
        let _ = self.requests.force_push(request);
        self.planner.unpark();
    }

    pub fn poll(&self) -> Option<StopPlan> {
        self.plans.pop()
    }
}

/// The planner thread; joins on drop.
pub struct StopPlanner {
    counts: Arc<(AtomicU64, AtomicU64)>,
    shutdown: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl StopPlanner {
    /// Start the planner with room for a stop of up to `max_seconds` at period `dt`.
    pub fn start(
        limits: MoveLimits,
        dt: f64,
        max_seconds: f64,
    ) -> std::io::Result<(Self, StopRequester)> {
        let requests = Arc::new(ArrayQueue::<StopRequest>::new(1));
        let plans = Arc::new(ArrayQueue::new(1));
        let shutdown = Arc::new(AtomicBool::new(false));
        let capacity = ((max_seconds / dt).ceil() as usize).max(2);
        let mut buffer = Some(vec![JointState::default(); capacity].into_boxed_slice());
        let (req, out, stop) = (Arc::clone(&requests), Arc::clone(&plans), Arc::clone(&shutdown));
        let counts = Arc::new((AtomicU64::new(0), AtomicU64::new(0)));
        let planned = Arc::clone(&counts);
        let handle = thread::Builder::new().name("hitl-stop-planner".into()).spawn(move || {
            while !stop.load(Ordering::Acquire) {
                let Some(request) = req.pop() else {
                    thread::park_timeout(Duration::from_millis(20));
                    continue;
                };
                let Some(mut samples) = buffer.take() else { continue };
                let len = plan_stop(&request.from, &limits, dt, &mut samples).unwrap_or(0);
                let _ = out.force_push(StopPlan { from_tick: request.from_tick, samples, len });
                planned.1.fetch_add(1, Ordering::AcqRel);
            }
        })?;
        let planner = handle.thread().clone();
        Ok((
            Self { counts: Arc::clone(&counts), shutdown, handle: Some(handle) },
            StopRequester { counts, requests, plans, planner },
        ))
    }

    /// Whether every stop requested so far has been planned (and its plan handed over).
    pub fn settled(&self) -> bool {
        self.counts.1.load(Ordering::Acquire) >= self.counts.0.load(Ordering::Acquire)
    }
}

impl Drop for StopPlanner {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            h.thread().unpark();
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_comes_back_as_a_plan_indexed_by_tick() {
        let limits = MoveLimits::uniform(1.0, 4.0, 60.0);
        let (_planner, requester) = StopPlanner::start(limits, 0.004, 5.0).expect("start");
        let from = JointState {
            q: [0.1; hitl_hal::DOF],
            qd: [0.5; hitl_hal::DOF],
            qdd: [0.0; hitl_hal::DOF],
        };
        requester.request(StopRequest { from, from_tick: 100 });
        let plan = (0..500)
            .find_map(|_| {
                thread::sleep(Duration::from_millis(1));
                requester.poll()
            })
            .expect("plan arrives");
        assert!(!plan.is_empty());
        assert!(plan.at(100).is_none(), "sample 0 is for the tick after the trip");
        let first = plan.at(101).expect("first sample");
        assert!(first.q[0] > 0.1 && first.q[0] < 0.1 + 0.5 * 0.004 + 1e-6);
        assert_eq!(plan.last().expect("end").qd, [0.0; hitl_hal::DOF]);
        assert!(plan.at(101 + plan.len() as u64).is_none());
    }
}
