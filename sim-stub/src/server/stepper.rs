//! The physics thread: advances the box and plant by a fixed step against absolute deadlines,
//! and releases scheduled faults on time.

use super::{Shared, POLL};
use crate::faults::{Fault, FaultSchedule};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Behind by more than this, the thread stops trying to catch up (and counts the slip).
///
/// A box's servo loop never falls behind, so a starved physics thread catches up on wall time:
/// after a stall of up to this long it steps back-to-back (a step is about 23 us, so half a
/// second of simulated time takes about 6 ms) and the simulated arm is again where a box's
/// would be. With 50 ms here, a loaded machine let the simulated arm lag its commands by a
/// tenth of a second, which the controller rightly called a joint deviation. Longer stalls
/// slip and are counted (`late_steps`), since a plant that far behind is no longer a box.
const MAX_CATCH_UP: Duration = Duration::from_millis(500);

pub fn run(shared: Arc<Shared>, faults: Vec<Fault>) {
    let dt = shared.physics_dt;
    let step = Duration::from_secs_f64(dt);
    let mut schedule = FaultSchedule::new(faults);
    let mut next = Instant::now();
    while !shared.stopping() {
        let t_s = shared.started.elapsed().as_secs_f64();
        while let Some(f) = schedule.next_due(t_s) {
            shared.apply(f.kind);
        }
        let t0 = Instant::now();
        shared.lock_arm().step(dt);
        let busy = t0.elapsed();
        let c = &shared.counters;
        c.steps.fetch_add(1, Ordering::Relaxed);
        c.step_busy_ns.fetch_add(busy.as_nanos() as u64, Ordering::Relaxed);
        next += step;
        let now = Instant::now();
        if now < next {
            std::thread::sleep((next - now).min(POLL));
        } else if now - next > MAX_CATCH_UP {
            c.late_steps.fetch_add(1, Ordering::Relaxed);
            next = now;
        }
    }
}
