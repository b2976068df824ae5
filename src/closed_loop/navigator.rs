//! The navigator: the closed loop's thread. It takes each pose estimate of the perception
//! worker, turns it into a measured deviation from the plan, runs the filter and its gate,
//! asks guidance for a correction, plans and checks the segment that plays it, and hands that to
//! the tick. It also watches for captures whose estimate never came (missing), counts unusable
//! captures in a row and falls back to the plan when there are too many, and records every
//! decision on the `/closed_loop/*` topics (docs/mcap-topics.md). It never blocks the tick:
//! everything between them goes through lock-free queues (`crate::control::correction`).

use super::filter::{Gate, RelNavFilter};
use super::guidance::wanted_correction;
use super::lockstep::{wait_until, TurnTaker, GIVE_UP};
use super::segment::{CartState, PlanTicks, Planned, SegmentRules};
use super::{corridor::Corridor, filter::FilterNoise, ClosedLoopConfig, PlanFrame};
use crate::control::correction::{CorrectionQueues, CorrectionSegment};
use crate::telemetry::LoopStatus;
use hitl_hal::{Clock, JointState, Joints, MonotonicClock};
use hitl_perception::{PoseResult, WorkerHandle};
use hitl_record::{ClosedLoopTopic, EventKind, SafetyEventMsg, Telemetry};
use hitl_trajectories::kinematics::camera_pose;
use hitl_trajectories::lab::LabConfig;
use nalgebra::Point3;
use serde_json::json;
use std::collections::{BTreeSet, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Segment buffers in circulation between the navigator and the tick.
const BUFFERS: usize = 4;
/// A new segment starts this long after the tick the navigator last saw (time to reach the tick).
const LEAD_S: f64 = 0.3;

/// What the navigator needs from the run.
pub struct NavigatorInputs {
    pub frame: PlanFrame,
    pub config: ClosedLoopConfig,
    /// The controller's lab (the preflight's rules, the camera mount).
    pub lab: LabConfig,
    pub plan: PlanTicks,
    /// Loop ticks of the playback's captures, in order.
    pub capture_ticks: Vec<u64>,
    pub dt: f64,
    pub results: crossbeam::channel::Receiver<PoseResult>,
    pub queues: CorrectionQueues,
    pub status: Arc<LoopStatus>,
    pub record: Option<Telemetry>,
    pub clock: MonotonicClock,
    /// The perception worker, for the drill that stops it.
    pub perception: Option<WorkerHandle>,
    /// On a simulated clock: the turns the lockstep gives (`super::lockstep`); on the host's
    /// clock, none: estimates are taken as they come.
    pub turns: Option<TurnTaker>,
}

/// What the closed loop did, for the run's summary and metadata.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NavigatorSummary {
    pub accepted: u64,
    pub gated: u64,
    pub lost: u64,
    pub late: u64,
    pub missing: u64,
    pub segments: u64,
    /// Corrections the preflight's rules or the corridor refused.
    pub refused: u64,
    /// Why the closed loop fell back to the plan, if it did.
    pub fallback: Option<String>,
    /// Largest camera correction sent, lab metres.
    pub max_correction_m: f64,
}

impl NavigatorSummary {
    pub fn describe(&self) -> String {
        format!(
            "closed loop: estimates used {}, gated {}, lost {}, late {}, missing {}; corrections sent {} \
             (largest {:.2} mm), refused {}; {}",
            self.accepted,
            self.gated,
            self.lost,
            self.late,
            self.missing,
            self.segments,
            self.max_correction_m * 1e3,
            self.refused,
            match &self.fallback {
                Some(why) => format!("fell back to the plan: {why}"),
                None => "no fallback".into(),
            }
        )
    }
}

/// The running navigator; [`Navigator::finish`] stops and joins it.
pub struct Navigator {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<NavigatorSummary>>,
}

impl Navigator {
    pub fn spawn(inputs: NavigatorInputs) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let handle =
            std::thread::Builder::new().name("hitl-navigator".into()).spawn(move || {
                let _ended = inputs.turns.as_ref().map(|t| EndTurns(Arc::clone(&t.turns)));
                State::new(inputs).run(&flag)
            })?;
        Ok(Self { stop, handle: Some(handle) })
    }

    /// Stop the thread and say what it did.
    pub fn finish(mut self) -> NavigatorSummary {
        self.stop.store(true, Ordering::Release);
        self.handle.take().and_then(|h| h.join().ok()).unwrap_or_default()
    }
}

impl Drop for Navigator {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Tells the lockstep that no more turns will be taken when the navigator's thread ends, even
/// by a panic (the lockstep would otherwise wait for each turn in vain).
struct EndTurns(Arc<super::lockstep::NavigatorTurns>);

impl Drop for EndTurns {
    fn drop(&mut self) {
        self.0.end();
    }
}

/// Why a capture's estimate was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Unusable {
    Lost,
    Late,
    Gated,
    Missing,
}

impl Unusable {
    fn name(self) -> &'static str {
        match self {
            Unusable::Lost => "lost",
            Unusable::Late => "late",
            Unusable::Gated => "gated",
            Unusable::Missing => "missing",
        }
    }
}

/// A segment the navigator sent: its id, first tick, corrections and offsets (a copy, to know
/// the offset of any past tick and the state a new segment starts from).
struct Sent {
    id: u64,
    from_tick: u64,
    planned: Planned,
}

impl Sent {
    fn index(&self, k: u64) -> Option<usize> {
        k.checked_sub(self.from_tick)
            .map(|i| i as usize)
            .filter(|i| *i < self.planned.offsets.len())
    }

    fn at(&self, k: u64) -> JointState {
        self.index(k).map(|i| self.planned.offsets[i]).unwrap_or_default()
    }

    fn cart_at(&self, k: u64) -> CartState {
        self.index(k).map(|i| self.planned.cart[i]).unwrap_or_default()
    }
}

struct State {
    inp: NavigatorInputs,
    filter: RelNavFilter,
    corridor: Corridor,
    mount: hitl_hal::Pose,
    buffers: Vec<CorrectionSegment>,
    sent: VecDeque<Sent>,
    /// (tick, id) of every segment that took effect, in order.
    switches: Vec<(u64, u64)>,
    next_id: u64,
    seen: BTreeSet<u64>,
    next_capture: usize,
    in_a_row: u32,
    fallen_back: bool,
    return_sent: bool,
    drilled: bool,
    /// Taking turns in a simulated clock's lockstep.
    lockstep: bool,
    summary: NavigatorSummary,
}

impl State {
    fn new(inp: NavigatorInputs) -> Self {
        let noise = FilterNoise::lab_defaults(inp.frame.scale, inp.frame.time_scale);
        let capacity = ((2.0 * inp.config.hold_s + 3.0) / inp.dt).ceil() as usize;
        Self {
            filter: RelNavFilter::new(inp.frame.mean_motion_rad_s, noise),
            corridor: Corridor { radius_m: inp.config.corridor_m },
            mount: inp.lab.camera_mount(),
            buffers: (0..BUFFERS).map(|_| CorrectionSegment::with_capacity(capacity)).collect(),
            sent: VecDeque::new(),
            switches: Vec::new(),
            next_id: 1,
            seen: BTreeSet::new(),
            next_capture: 0,
            in_a_row: 0,
            fallen_back: false,
            return_sent: false,
            drilled: false,
            lockstep: false,
            summary: NavigatorSummary::default(),
            inp,
        }
    }

    fn rules(&self) -> SegmentRules<'_> {
        let i = &self.inp;
        SegmentRules {
            plan: &i.plan,
            lab: &i.lab,
            mount: self.mount,
            corridor: self.corridor,
            dt: i.dt,
            hold_ticks: (i.config.hold_s / i.dt).round() as u64,
            // The settle waits up to 2 s; the return is done within the first.
            return_by_tick: i.plan.end_tick() + (1.0 / i.dt) as u64,
            capacity: self.buffers.first().map_or(0, |b| b.capacity()),
        }
    }

    fn run(mut self, stop: &AtomicBool) -> NavigatorSummary {
        match self.inp.turns.take() {
            Some(turns) => self.run_in_turns(stop, &turns),
            None => self.run_freely(stop),
        }
    }

    fn running(&self, stop: &AtomicBool) -> bool {
        !stop.load(Ordering::Acquire) && !self.inp.status.done.load(Ordering::Acquire)
    }

    /// On the host's clock: each estimate as it comes, what is due at least every 10 ms.
    fn run_freely(mut self, stop: &AtomicBool) -> NavigatorSummary {
        while self.running(stop) {
            match self.inp.results.recv_timeout(Duration::from_millis(10)) {
                Ok(r) => {
                    self.drain_queues();
                    self.on_result(&r);
                }
                Err(crossbeam::channel::RecvTimeoutError::Timeout) => {}
                // Perception has ended: what is left is missing captures.
                Err(crossbeam::channel::RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(Duration::from_millis(10))
                }
            }
            self.due_work();
        }
        self.summary
    }

    /// On a simulated clock: only in the turns the lockstep gives, while the loop waits, so
    /// every decision is taken at the same tick in every run (`super::lockstep`).
    fn run_in_turns(mut self, stop: &AtomicBool, turns: &TurnTaker) -> NavigatorSummary {
        self.lockstep = true;
        while self.running(stop) {
            let Some(turn) = turns.next(Duration::from_millis(10)) else { continue };
            self.drain_queues();
            while let Ok(r) = self.inp.results.try_recv() {
                self.on_result(&r);
                turns.handled();
            }
            self.due_work();
            turns.over(turn, self.next_due());
        }
        self.summary
    }

    /// What is due by the loop's tick without a new estimate: the drill, the captures whose
    /// estimate is overdue, the return to the plan after a fallback.
    fn due_work(&mut self) {
        self.drain_queues();
        let now_tick = self.inp.status.tick.load(Ordering::Acquire);
        self.drill(now_tick);
        self.find_missing(now_tick);
        if self.fallen_back && !self.return_sent {
            self.send_return();
        }
    }

    /// The first tick at which [`Self::due_work`] may have something to do (each tick while
    /// the return to the plan waits to be sent).
    fn next_due(&self) -> u64 {
        if self.fallen_back && !self.return_sent {
            return 0;
        }
        let missing = self
            .inp
            .capture_ticks
            .get(self.next_capture)
            .map_or(u64::MAX, |k| k + self.missing_after_ticks() + 1);
        let drill = match self.drill_tick() {
            Some(at) if !self.drilled => at,
            _ => u64::MAX,
        };
        missing.min(drill)
    }

    fn drain_queues(&mut self) {
        while let Some(s) = self.inp.queues.switches.pop() {
            self.switches.push((s.tick, s.id));
        }
        while let Some(b) = self.inp.queues.spent.pop() {
            self.buffers.push(b);
        }
    }

    fn now_ns(&self) -> u64 {
        self.inp.clock.now_ns()
    }

    fn record(&self, topic: ClosedLoopTopic, value: serde_json::Value) {
        if let Some(r) = &self.inp.record {
            r.push_closed_loop(topic, self.now_ns(), value);
        }
    }

    fn event(&self, detail: String) {
        crate::errln!("{detail}");
        if let Some(r) = &self.inp.record {
            r.push_event(SafetyEventMsg::text(self.now_ns(), EventKind::Other, detail));
        }
    }

    /// The loop tick `s` seconds into the playback.
    fn playback_tick(&self, s: f64) -> u64 {
        self.inp.plan.first_tick + (s / self.inp.dt) as u64
    }

    /// When `--drill-perception-stop-s` stops the perception worker.
    fn drill_tick(&self) -> Option<u64> {
        self.inp.config.drill_perception_stop_s.map(|s| self.playback_tick(s))
    }

    /// `--drill-perception-stop-s`: the perception worker is told to stop.
    fn drill(&mut self, now_tick: u64) {
        let Some(at) = self.drill_tick() else { return };
        if self.drilled || now_tick < at {
            return;
        }
        self.drilled = true;
        if let Some(p) = &self.inp.perception {
            p.close();
            // In lockstep, the turn ends with the worker: a frame the next tick hands it is
            // then never estimated, in every run alike.
            if self.lockstep {
                let ended = &p.stats.ended;
                wait_until(GIVE_UP, || ended.load(Ordering::Acquire));
            }
        }
        let s = self.inp.config.drill_perception_stop_s.unwrap_or_default();
        self.event(format!("closed loop drill: perception stopped {s} s into the playback"));
    }

    /// `--drill-perception-offset-m`: what the drill adds to the estimate of the capture at
    /// loop tick `k` (camera frame, lab metres).
    fn drilled_offset(&self, k: u64) -> nalgebra::Vector3<f64> {
        match self.inp.config.drill_perception_offset {
            Some(d) if k >= self.playback_tick(d.from_s) => nalgebra::Vector3::x() * d.offset_m,
            _ => nalgebra::Vector3::zeros(),
        }
    }

    /// The offset the tick applied at `k` (from the switches it reported).
    fn offset_at(&self, k: u64) -> JointState {
        self.in_effect_at(k).map_or_else(JointState::default, |s| s.at(k))
    }

    /// The camera correction the tick applied at `k` (base frame, lab metres).
    fn correction_at(&self, k: u64) -> nalgebra::Vector3<f64> {
        self.in_effect_at(k).map_or_else(nalgebra::Vector3::zeros, |s| s.cart_at(k).p)
    }

    /// The segment in effect at tick `k` (from the switches the tick reported).
    fn in_effect_at(&self, k: u64) -> Option<&Sent> {
        let &(_, id) = self.switches.iter().rev().find(|(t, _)| *t <= k)?;
        self.sent.iter().find(|s| s.id == id)
    }

    fn on_result(&mut self, r: &PoseResult) {
        let k = r.seq;
        let Some(planned) = self.inp.plan.at(k) else { return };
        if !self.seen.insert(k) {
            return;
        }
        let age_s = self.now_ns().saturating_sub(r.timestamp_ns) as f64 * 1e-9;
        let pose = match &r.estimate {
            Ok(e) => e.pose,
            Err(_) => None,
        };
        let Some(pose) = pose else {
            return self.unusable(k, Unusable::Lost, json!({}));
        };
        if age_s > self.inp.config.max_age_s {
            return self.unusable(k, Unusable::Late, json!({ "age_s": age_s }));
        }
        // The measured deviation: minus where the target was seen, from where the plan put it.
        let off = self.offset_at(k);
        let q: Joints = std::array::from_fn(|j| planned.q[j] + off.q[j]);
        let cam = camera_pose(&q, &self.mount);
        let seen = cam * Point3::from(pose.translation.vector + self.drilled_offset(k));
        let z_lab = -(seen.coords - self.inp.frame.target_base_m);
        let in_effect = self.correction_at(k);
        let z = self.inp.frame.lab_to_rtn(&z_lab);
        let t_orbit =
            (k - self.inp.plan.first_tick) as f64 * self.inp.dt * self.inp.frame.time_scale;
        let sigma = self.filter.default_sigma_m();
        let gate = self.filter.update(t_orbit, &z, sigma);
        let x = self.filter.state();
        let p = self.filter.covariance();
        self.record(
            ClosedLoopTopic::Filter,
            json!({
                "tick": k, "t_orbit_s": t_orbit,
                "state": x.as_slice(), "covariance": p.as_slice(),
                "deviation_lab_m": self.inp.frame.rtn_to_lab(&self.filter.position()).as_slice(),
            }),
        );
        match gate {
            Gate::Rejected { mahalanobis2 } => self.unusable(
                k,
                Unusable::Gated,
                json!({ "mahalanobis2": finite(mahalanobis2), "measured_lab_m": z_lab.as_slice(),
                        "correction_lab_m": in_effect.as_slice() }),
            ),
            Gate::Accepted { mahalanobis2 } => {
                self.in_a_row = 0;
                self.summary.accepted += 1;
                self.record(
                    ClosedLoopTopic::Gate,
                    json!({ "tick": k, "used": true, "reason": "accepted", "mahalanobis2": mahalanobis2,
                            "measured_lab_m": z_lab.as_slice(), "correction_lab_m": in_effect.as_slice() }),
                );
                if !self.fallen_back {
                    self.correct();
                }
            }
        }
    }

    fn unusable(&mut self, k: u64, why: Unusable, extra: serde_json::Value) {
        match why {
            Unusable::Lost => self.summary.lost += 1,
            Unusable::Late => self.summary.late += 1,
            Unusable::Gated => self.summary.gated += 1,
            Unusable::Missing => self.summary.missing += 1,
        }
        self.in_a_row += 1;
        let mut v =
            json!({ "tick": k, "used": false, "reason": why.name(), "in_a_row": self.in_a_row });
        if let (Some(o), Some(e)) = (v.as_object_mut(), extra.as_object()) {
            o.extend(e.clone());
        }
        self.record(ClosedLoopTopic::Gate, v);
        if !self.fallen_back && self.in_a_row >= self.inp.config.fallback_after {
            self.fallen_back = true;
            let why = format!(
                "{} unusable captures in a row (the last {}, at tick {k})",
                self.in_a_row,
                why.name()
            );
            self.event(format!("closed loop fell back to the plan: {why}"));
            self.summary.fallback = Some(why);
        }
    }

    /// Ticks after its capture at which a capture's estimate is missing.
    fn missing_after_ticks(&self) -> u64 {
        (self.inp.config.max_age_s / self.inp.dt).ceil() as u64
    }

    /// Captures whose estimate has not come `max_age_s` after them.
    fn find_missing(&mut self, now_tick: u64) {
        let wait = self.missing_after_ticks();
        while let Some(&k) = self.inp.capture_ticks.get(self.next_capture) {
            if k + wait >= now_tick {
                break;
            }
            self.next_capture += 1;
            if self.seen.insert(k) {
                self.unusable(k, Unusable::Missing, json!({}));
            }
        }
    }

    /// Where a new segment starts, the segment in effect there and its correction and offset
    /// there; `None` while a segment sent earlier has not taken effect yet (a new one would be
    /// built on a guess).
    fn next_start(&self) -> Option<(u64, u64, CartState, JointState)> {
        let now = self.inp.status.tick.load(Ordering::Relaxed);
        if let Some(last) = self.sent.back() {
            let switched = self.switches.iter().any(|(_, id)| *id == last.id);
            if !switched && last.from_tick + 2 > now {
                return None;
            }
        }
        let from = (now + (LEAD_S / self.inp.dt).ceil() as u64).max(self.inp.plan.first_tick);
        let active = self.inp.queues.stats.active.load(Ordering::Relaxed);
        let base = self.sent.iter().find(|s| s.id == active);
        let cart = base.map_or_else(CartState::default, |s| s.cart_at(from));
        let offset = base.map_or_else(JointState::default, |s| s.at(from));
        Some((from, active, cart, offset))
    }

    fn correct(&mut self) {
        let Some((from, base, cart, offset)) = self.next_start() else { return };
        if from >= self.inp.plan.end_tick() {
            return;
        }
        let (wanted, clamped) =
            wanted_correction(&self.inp.frame, &self.filter.position(), &self.corridor);
        match self.rules().plan(from, &cart, &offset, Some(&wanted)) {
            Ok(planned) => {
                let ticks = planned.offsets.len();
                if self.send(from, base, planned) {
                    self.summary.max_correction_m =
                        self.summary.max_correction_m.max(wanted.norm());
                    self.record(
                        ClosedLoopTopic::Correction,
                        json!({ "tick": from, "id": self.next_id - 1, "based_on": base,
                                "correction_lab_m": wanted.as_slice(), "clamped": clamped,
                                "ticks": ticks }),
                    );
                }
            }
            Err(why) => self.refused(from, &why),
        }
    }

    fn refused(&mut self, from: u64, why: &str) {
        self.summary.refused += 1;
        self.record(ClosedLoopTopic::Correction, json!({ "tick": from, "refused": why }));
    }

    /// After the fallback: one segment from the offset in effect back to the plan.
    fn send_return(&mut self) {
        let Some((from, base, cart, offset)) = self.next_start() else { return };
        if base == 0 {
            self.return_sent = true;
            return;
        }
        match self.rules().plan(from, &cart, &offset, None) {
            Ok(planned) => {
                if self.send(from, base, planned) {
                    self.return_sent = true;
                    self.record(ClosedLoopTopic::Correction, json!({ "tick": from, "id": self.next_id - 1, "based_on": base, "return_to_plan": true }));
                }
            }
            Err(why) => {
                // The segment in effect already ends on the plan: nothing more can be done.
                self.return_sent = true;
                self.refused(from, &why);
            }
        }
    }

    fn send(&mut self, from: u64, base: u64, planned: Planned) -> bool {
        let Some(mut buf) = self.buffers.pop() else { return false };
        let id = self.next_id;
        if !buf.fill(id, base, from, &planned.offsets) {
            self.buffers.push(buf);
            return false;
        }
        self.next_id += 1;
        if let Some(displaced) = self.inp.queues.incoming.force_push(buf) {
            self.buffers.push(displaced);
        }
        self.sent.push_back(Sent { id, from_tick: from, planned });
        // Keep the segments a capture still waiting for its estimate may have been taken under.
        while self.sent.len() > 16 {
            self.sent.pop_front();
        }
        self.summary.segments += 1;
        true
    }
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}
