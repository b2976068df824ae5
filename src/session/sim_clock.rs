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
//!    intake, every frame estimated (or the perception worker ended) and every estimate passed on
//!    to the closed loop's navigator (without a closed loop, only once the next frame is
//!    rendered: perception works on while the ticks go on); and until a requested stop has
//!    been planned;
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
#[cfg(feature = "stub")]
use crate::rt::World;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
#[cfg(feature = "stub")]
use std::time::Instant;

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

/// The longest a lockstep wait waits for the world, host time, before it gives up on it: a
/// thread that died, not a slow one (a 1280x1024 capture's render and first registration took
/// over 10 s on the shared 2-core machine at load 18, and the run then did not repeat exactly).
pub const STALL: Duration = Duration::from_secs(60);

/// A lockstep wait's first sleep, once its yields found the world still busy; each next one is
/// twice as long, up to [`PAUSE_MAX`].
const PAUSE_MIN: Duration = Duration::from_micros(25);
const PAUSE_MAX: Duration = Duration::from_micros(800);

/// The report reader's progress, shared with the lockstep.
#[derive(Debug, Default)]
pub struct ReaderProgress {
    /// Reports published to the loop.
    pub published: AtomicU64,
    /// The reader thread has ended (its stream failed or it was told to stop).
    pub ended: AtomicBool,
}

/// Where a simulated run's host time went between ticks, and the waits that gave up; shared by
/// the lockstep's world and the session that reports it.
#[derive(Debug, Default)]
pub struct WorldTimes {
    /// Lockstep waits that gave up after [`STALL`].
    pub stalls: AtomicU64,
    /// Host ns waiting for the stub to answer the commands written.
    pub commands_ns: AtomicU64,
    /// Host ns waiting for the capture path (render, intake, estimate, stop plan).
    pub capture_ns: AtomicU64,
    /// Host ns stepping the stub (physics, faults, reports written).
    pub stub_ns: AtomicU64,
    /// Host ns waiting for the report reader.
    pub reports_ns: AtomicU64,
}

impl WorldTimes {
    /// Host seconds in each part of the lockstep: commands, capture path, stub, reports.
    pub fn seconds(&self) -> [f64; 4] {
        [&self.commands_ns, &self.capture_ns, &self.stub_ns, &self.reports_ns]
            .map(|a| a.load(Ordering::Relaxed) as f64 * 1e-9)
    }

    /// How the run went: `sim_ns` of simulated time played in `wall_s` host seconds.
    pub fn stats(&self, sim_ns: u64, wall_s: f64) -> SimStats {
        SimStats {
            sim_s: sim_ns as f64 * 1e-9,
            wall_s,
            stalls: self.stalls.load(Ordering::Relaxed),
            lockstep_s: self.seconds(),
        }
    }
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
    /// Host seconds between ticks spent on: the stub's answers to the commands, the capture
    /// path, stepping the stub, the report reader ([`WorldTimes::seconds`]); the rest of
    /// `wall_s` is the ticks themselves and the hand-over between threads.
    pub lockstep_s: [f64; 4],
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

    /// Where the loop's host time went (a second line of the summary: the first stays the one
    /// `hitl campaign` reads the factor from).
    pub fn describe_lockstep(&self) -> String {
        let [c, p, s, r] = self.lockstep_s;
        format!(
            "lockstep host time: {c:.3} s stub answering commands, {p:.3} s capture path \
             (render, intake, estimate), {s:.3} s stepping the stub, {r:.3} s report reader, \
             {:.3} s ticks and hand-over",
            (self.wall_s - c - p - s - r).max(0.0)
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
    /// Whether the loop acts on the estimates (`--closed-loop`): then each is made before the
    /// next tick. Otherwise perception may finish a frame while the ticks go on and the next
    /// capture renders, and must be idle only before the next frame reaches the intake (the
    /// estimates, stamped with their frames' exposures, are the same either way).
    pub estimates_steer: bool,
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
    pub times: &'a WorldTimes,
}

#[cfg(feature = "stub")]
impl SimWorld<'_> {
    /// Wait until `done`, at most [`STALL`]; a give-up is counted, the host time added to
    /// `spent`.
    fn wait(&self, spent: &AtomicU64, done: impl Fn() -> bool) {
        if done() {
            return;
        }
        let start = Instant::now();
        let (mut spins, mut pause) = (0u32, PAUSE_MIN);
        while !done() {
            if start.elapsed() > STALL {
                self.times.stalls.fetch_add(1, Ordering::Relaxed);
                break;
            }
            // A few yields (an answer from the stub or the reader is microseconds away), then
            // sleeps that grow to PAUSE_MAX: a render or an estimate takes milliseconds, and
            // the loop thread (SCHED_FIFO) waking every few microseconds to look took a quarter
            // of the CPU the renderer needed.
            if spins < 50 {
                spins += 1;
                std::thread::yield_now();
            } else {
                std::thread::sleep(pause);
                pause = (pause * 2).min(PAUSE_MAX);
            }
        }
        spent.fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
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
        let perception_idle = || {
            w.perception.as_ref().is_none_or(|s| {
                let produced =
                    s.estimated.load(Ordering::Acquire) + s.errors.load(Ordering::Acquire);
                let estimated = s.ended.load(Ordering::Acquire)
                    || produced + s.dropped.load(Ordering::Acquire)
                        >= s.pushed.load(Ordering::Acquire);
                estimated && w.navigator.as_ref().is_none_or(|n| n.flow().forwarded_all(produced))
            })
        };
        // A rendered frame the tick has not polled yet goes to the intake, then to perception,
        // at the next tick: the previous estimate must be made by then (a frame the camera
        // dropped keeps this true, and perception in step with the ticks).
        let frame_next = self.stub.frames_rendered() > q.frames_in.load(Ordering::Acquire);
        self.stub.renders_done()
            && intake_idle
            && (!(w.estimates_steer || frame_next) || perception_idle())
            && (self.stop_planned)()
    }

    /// The navigator's turn, when it has one due (its wait counts as the capture path's).
    fn navigator_turn(&self) {
        if let Some(n) = self.watched.navigator.as_ref().filter(|n| n.due()) {
            let turn = n.give();
            self.wait(&self.times.capture_ns, || n.taken(turn));
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
        let t = self.times;
        self.wait(&t.commands_ns, || self.commands_answered());
        self.wait(&t.capture_ns, || self.capture_path_idle());
        self.navigator_turn();
        let start = Instant::now();
        self.stub.advance_to(t_ns);
        t.stub_ns.fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        self.wait(&t.reports_ns, || self.reports_read());
    }
}
