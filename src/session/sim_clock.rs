//! `--clock realtime|sim`: which time a run lives on, and on `sim` the simulated world the loop
//! advances in lockstep (docs/sim-clock.md).
//!
//! On `sim` one simulated time ([`hitl_hal::SimTime`]) is the run's clock: the tick, the report
//! reader, the camera's exposures and the recorder stamp with it. The loop's pace
//! ([`crate::rt::Lockstep`]) moves it by one period per tick and hands the deadline to
//! [`SimWorld`], which, before the tick runs:
//!
//! 1. waits until the embedded stub has answered every command the arm client wrote (the
//!    previous tick's setpoint acts on the physics that follows, as on a box that hears it at
//!    once);
//! 2. waits until the capture path is idle: every capture rendered, every frame through the
//!    intake, every frame estimated (or the perception worker ended), every estimate passed on to
//!    the closed loop's navigator; and until a requested stop has been planned;
//! 3. with `--closed-loop`, gives the navigator a turn when it has one due (an estimate waiting,
//!    a capture's estimate overdue) and waits until it is over (`crate::closed_loop::lockstep`);
//! 4. steps the stub to the deadline (faults due, reports due, physics);
//! 5. waits until the report reader has read every report the stub wrote.
//!
//! So what the tick sees depends on simulated time alone, never on how fast the machine is or
//! how loaded. Each wait is bounded by [`STALL`] of host time: a world that stops answering
//! (a thread that died) is counted and the run goes on rather than hanging.

use crate::capture::sink::IntakeQueues;
use crate::closed_loop::lockstep::NavigatorTurns;
#[cfg(feature = "stub")]
use crate::devices::stub::EmbeddedStub;
use crate::rt::World;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Which time a run lives on (`--clock`, `[run] clock`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockChoice {
    /// The host's monotonic clock: the loop keeps wall-clock deadlines.
    #[default]
    Realtime,
    /// Simulated time, advanced by whole ticks in lockstep with the embedded stub.
    Sim,
}

impl ClockChoice {
    pub fn as_str(self) -> &'static str {
        match self {
            ClockChoice::Realtime => "realtime",
            ClockChoice::Sim => "sim",
        }
    }
}

impl std::fmt::Display for ClockChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The longest a lockstep wait waits for the world, host time, before it gives up on it.
pub const STALL: Duration = Duration::from_secs(10);

/// The report reader's progress, shared with the lockstep.
#[derive(Debug, Default)]
pub struct ReaderProgress {
    /// Reports published to the loop.
    pub published: AtomicU64,
    /// The reader thread has ended (its stream failed or it was told to stop).
    pub ended: AtomicBool,
}

/// How a simulated run went, in host time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimStats {
    /// Simulated seconds the loop played.
    pub sim_s: f64,
    /// Host seconds the loop took.
    pub wall_s: f64,
    /// Lockstep waits that gave up after [`STALL`] (0 in a run that repeats exactly).
    pub stalls: u64,
}

impl SimStats {
    /// Simulated seconds per host second.
    pub fn real_time_factor(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.sim_s / self.wall_s
        } else {
            0.0
        }
    }

    pub fn describe(&self) -> String {
        format!(
            "simulated clock: {:.3} s simulated in {:.3} s ({:.2}x real time){}",
            self.sim_s,
            self.wall_s,
            self.real_time_factor(),
            if self.stalls > 0 {
                format!(
                    "; {} lockstep wait(s) gave up after {} s: this run may not repeat exactly",
                    self.stalls,
                    STALL.as_secs()
                )
            } else {
                String::new()
            }
        )
    }
}

/// What the lockstep waits on, besides the stub itself.
pub struct Watched {
    /// Request frames the arm client has written.
    pub commands_written: Arc<AtomicU64>,
    pub reader: Arc<ReaderProgress>,
    pub intake: Arc<IntakeQueues>,
    pub perception: Option<Arc<hitl_perception::WorkerStats>>,
    /// `--closed-loop`: the navigator's turns.
    pub navigator: Option<Arc<NavigatorTurns>>,
}

/// The simulated world of a `--clock sim` run: the embedded stub and the capture path.
#[cfg(feature = "stub")]
pub struct SimWorld<'a> {
    pub stub: &'a EmbeddedStub,
    pub watched: &'a Watched,
    /// Whether the stop planner has planned every stop asked of it.
    pub stop_planned: &'a (dyn Fn() -> bool + Sync),
    pub stalls: &'a AtomicU64,
}

#[cfg(feature = "stub")]
impl SimWorld<'_> {
    /// Wait until `done`, at most [`STALL`]; a give-up is counted.
    fn wait(&self, done: impl Fn() -> bool) {
        if done() {
            return;
        }
        let start = Instant::now();
        let mut spins = 0u32;
        while !done() {
            if start.elapsed() > STALL {
                self.stalls.fetch_add(1, Ordering::Relaxed);
                return;
            }
            // A few yields (the answer is usually microseconds away), then short sleeps so
            // that a slow render leaves the CPU to the renderer.
            if spins < 50 {
                spins += 1;
                std::thread::yield_now();
            } else {
                std::thread::sleep(Duration::from_micros(50));
            }
        }
    }

    fn commands_answered(&self) -> bool {
        let Some(sim) = self.stub.sim() else { return true };
        sim.commands_answered.load(Ordering::Acquire)
            >= self.watched.commands_written.load(Ordering::Acquire)
            || sim.command_connections.load(Ordering::Acquire) == 0
            || self.stub.replies_stalled()
    }

    fn capture_path_idle(&self) -> bool {
        let w = self.watched;
        let q = &w.intake;
        let intake_idle = q.frames_done.load(Ordering::Acquire)
            + q.frames_lost.load(Ordering::Acquire)
            >= q.frames_in.load(Ordering::Acquire);
        let perception_idle = w.perception.as_ref().is_none_or(|s| {
            let produced = s.estimated.load(Ordering::Acquire) + s.errors.load(Ordering::Acquire);
            let estimated = s.ended.load(Ordering::Acquire)
                || produced + s.dropped.load(Ordering::Acquire) >= s.pushed.load(Ordering::Acquire);
            estimated && w.navigator.as_ref().is_none_or(|n| n.flow().forwarded_all(produced))
        });
        self.stub.renders_done() && intake_idle && perception_idle && (self.stop_planned)()
    }

    /// The navigator's turn, when it has one due.
    fn navigator_turn(&self) {
        if let Some(n) = self.watched.navigator.as_ref().filter(|n| n.due()) {
            let turn = n.give();
            self.wait(|| n.taken(turn));
        }
    }

    fn reports_read(&self) -> bool {
        let Some(sim) = self.stub.sim() else { return true };
        let r = &self.watched.reader;
        r.ended.load(Ordering::Acquire)
            || r.published.load(Ordering::Acquire)
                >= sim.reports_written(hitl_drivers::xarm::report::ReportKind::Real)
    }
}

#[cfg(feature = "stub")]
impl World for SimWorld<'_> {
    fn advance_to(&mut self, t_ns: u64) {
        self.wait(|| self.commands_answered());
        self.wait(|| self.capture_path_idle());
        self.navigator_turn();
        self.stub.advance_to(t_ns);
        self.wait(|| self.reports_read());
    }
}
