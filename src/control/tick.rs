//! The real-time loop. One [`ControlLoop::tick`] per period: sense, check the interlocks, pick the
//! setpoint, send it, fire captures and light, hand out telemetry. Everything it reads was
//! prepared before the loop ([`Program`]); it allocates nothing, takes no lock, awaits nothing
//! and writes no log. Statistics leave through the telemetry sink and [`LoopStatus`].
//!
//! The loop borrows its devices ([`Devices`] of `&mut` references, which implement the hal
//! traits like the devices themselves): the session opens, starts and stops them around it. Each
//! tick asks every device for its health (hal's `Lifecycle::health`), so a device whose I/O task
//! failed trips the run within one period even when the tick had nothing to ask it.

use super::correction::CorrectionStage;
use super::interlocks::{Interlocks, Reaction, Sense};
use super::stop::{StopPlan, StopRequest, StopRequester};
use crate::rt::{probe, slot::SlotReader, Pace, Periodic, Wake};
use crate::telemetry::{CaptureOut, LoopStatus, SetpointOut, TelemetrySink, TimingOut};
use crate::telemetry::{Device, Trip, TripKind};
use hitl_hal::{
    Arm, ArmState, CaptureRequest, Clock, Error as _, ErrorKind, Inputs, Lifecycle, Light,
    MonotonicClock, RgbdCamera, Trigger, TriggerLines,
};
use hitl_hal::{JointState, Phase};
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Ticks the loop may bridge a trip by extrapolation while the stop plan is made (100 ms at
/// 250 Hz); past that it holds.
const MAX_BRIDGE_TICKS: u64 = 25;

/// Everything the loop plays, prepared (and checked) before it starts.
#[derive(Debug, Clone, Default)]
pub struct Program {
    /// The approach from the arm's pose to the first waypoint, one setpoint per tick.
    pub approach: Vec<JointState>,
    /// The time-parametrised trajectory, one setpoint per tick.
    pub playback: Vec<JointState>,
    /// Per playback tick: fire a capture.
    pub capture: Vec<bool>,
    /// Per playback tick: the light level (empty: leave the light alone).
    pub light: Vec<f32>,
    /// The light takes its level this many ticks before the tick it is scheduled for.
    pub light_lead_ticks: u64,
    /// Settle: hold the last setpoint until every joint is within this of it...
    pub settle_tolerance_rad: f64,
    /// ...or this many ticks have passed.
    pub settle_max_ticks: u64,
    /// The first this many playback setpoints are the lead-in (from rest into a file that starts
    /// moving) and the last `lead_out_ticks` the lead-out (to rest); recorded as phases of their
    /// own. Settling after a lead-out holds its end and is recorded as lead-out.
    pub lead_in_ticks: u64,
    pub lead_out_ticks: u64,
    /// After the playback has settled (or its settle timed out): the planned move back to the
    /// rest pose, one setpoint per tick, then a settle on its end (empty: the arm stays where the
    /// playback ended). Recorded as `retreat`.
    pub retreat: Vec<JointState>,
}

impl Program {
    fn approach_ticks(&self) -> u64 {
        self.approach.len() as u64
    }
    fn playback_end(&self) -> u64 {
        self.approach_ticks() + self.playback.len() as u64
    }

    /// The light level in effect at tick `k` of the playback: the schedule's level there, whose
    /// command went out `light_lead_ticks` earlier. `None` without a schedule, outside the
    /// playback, and in the first `light_lead_ticks` ticks of the run (that command would have
    /// had to go out before the loop started: the light shows whatever it had).
    pub fn light_in_effect(&self, k: u64) -> Option<f32> {
        if k < self.light_lead_ticks {
            return None;
        }
        let i = k.checked_sub(self.approach_ticks())?;
        self.light.get(usize::try_from(i).ok()?).copied()
    }
}

/// Flags raised outside the loop that the tick reads each period (lock-free).
#[derive(Debug, Default, Clone)]
pub struct Health {
    /// Ctrl-C.
    pub operator_stop: Arc<AtomicBool>,
    /// The recorder's own health flag, when the run records.
    pub recorder: Option<hitl_record::RecorderHealth>,
    /// A device failed outside the tick (frame intake, serial task): 0 none, else `Device` + 1.
    pub device_failed: Arc<AtomicU8>,
}

impl Health {
    /// Report a device failure from outside the tick.
    pub fn device_failed(&self, device: Device) {
        let code = device as u8 + 1;
        let _ = self.device_failed.compare_exchange(0, code, Ordering::AcqRel, Ordering::Acquire);
    }

    fn failed_device(&self) -> Option<Device> {
        match self.device_failed.load(Ordering::Acquire) {
            0 => None,
            1 => Some(Device::Camera),
            2 => Some(Device::Light),
            3 => Some(Device::Trigger),
            _ => Some(Device::Inputs),
        }
    }
}

/// The devices the loop drives; the loop does not know which implementations are behind them.
/// The session passes `&mut` borrows of the devices it owns.
pub struct Devices<A, C, L, I, G> {
    pub arm: A,
    pub camera: C,
    pub light: L,
    pub inputs: I,
    /// Hardware trigger lines (the trigger box): the camera line fires at every capture tick.
    pub trigger: G,
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Played to the end and settled on the last waypoint (`settled`: within the tolerance, not
    /// timed out); then, when the program has a retreat, back to rest (`at_rest`: settled there).
    Completed { ticks: u64, settled: bool, at_rest: Option<bool> },
    /// An interlock or the operator stopped it; `stopped` says the controlled stop completed.
    Tripped { trip: Trip, stopped: bool },
}

enum Flow {
    Continue,
    Done(Outcome),
}

/// The loop's connections to the rest of the controller.
pub struct LoopIo<T> {
    /// Arm reports from the reader thread.
    pub reports: SlotReader<ArmState>,
    pub telemetry: T,
    pub status: Arc<LoopStatus>,
    pub health: Health,
    pub stop: StopRequester,
    /// The clock arm reports are stamped on (the watchdog compares against it).
    pub clock: MonotonicClock,
}

/// The loop and all the state it keeps between ticks.
pub struct ControlLoop<'p, A, C, L, I, G, T> {
    program: &'p Program,
    devices: Devices<A, C, L, I, G>,
    reports: SlotReader<ArmState>,
    telemetry: T,
    status: Arc<LoopStatus>,
    health: Health,
    interlocks: Interlocks,
    stop: StopRequester,
    clock: MonotonicClock,
    dt: f64,
    last_sent: JointState,
    last_sent_tick: u64,
    trip: Option<Trip>,
    stop_plan: Option<StopPlan>,
    light_level: f32,
    captures: u32,
    device_failed: Option<Device>,
    /// The tick the retreat started at, and whether the playback had settled before it.
    retreat_from: Option<(u64, bool)>,
    /// `--closed-loop`: the navigator's checked offsets on the playback (open loop: nothing).
    correction: CorrectionStage,
}

impl<'p, A, C, L, I, G, T> ControlLoop<'p, A, C, L, I, G, T>
where
    A: Arm,
    C: RgbdCamera + Lifecycle,
    L: Light + Lifecycle,
    I: Inputs,
    G: Trigger + Lifecycle,
    T: TelemetrySink,
{
    /// A loop that starts from the arm at rest at `start`.
    pub fn new(
        program: &'p Program,
        devices: Devices<A, C, L, I, G>,
        io: LoopIo<T>,
        interlocks: Interlocks,
        rate_hz: f64,
        start: &hitl_hal::Joints,
    ) -> Self {
        Self {
            program,
            devices,
            reports: io.reports,
            telemetry: io.telemetry,
            status: io.status,
            health: io.health,
            interlocks,
            stop: io.stop,
            clock: io.clock,
            dt: 1.0 / rate_hz,
            last_sent: JointState::rest(*start),
            last_sent_tick: 0,
            trip: None,
            stop_plan: None,
            light_level: f32::NAN,
            captures: 0,
            device_failed: None,
            retreat_from: None,
            correction: CorrectionStage::open_loop(),
        }
    }

    /// The loop with a closed loop's correction stage (docs/closed-loop.md).
    pub fn with_correction(mut self, correction: CorrectionStage) -> Self {
        self.correction = correction;
        self
    }

    /// Run on the calling thread until the program ends or a trip has been handled. The caller
    /// has applied the OS real-time settings to this thread; the devices go back to it with the
    /// borrows when this returns.
    pub fn run(self, spin: Duration) -> Outcome {
        let mut pace = Periodic::new(Duration::from_secs_f64(self.dt), spin);
        self.run_paced(&mut pace)
    }

    /// [`Self::run`] on a pace of the caller's: the host's deadlines ([`Periodic`]) or whole
    /// periods of simulated time ([`crate::rt::Lockstep`]). The ticks are the same either way.
    pub fn run_paced(mut self, pace: &mut dyn Pace) -> Outcome {
        let outcome = {
            let _in_loop = probe::enter_rt_loop();
            loop {
                let wake = pace.wait();
                if let Flow::Done(outcome) = self.tick(wake) {
                    break outcome;
                }
            }
        };
        self.status.done.store(true, Ordering::Release);
        outcome
    }

    /// One period of work.
    fn tick(&mut self, wake: Wake) -> Flow {
        let k = wake.tick;
        let now = self.clock.now_ns();

        // 1. Sense.
        let (arm, fresh) = self.reports.latest();
        if let (Some(state), true) = (arm.as_ref(), fresh) {
            self.telemetry.arm_state(state);
        }
        let inputs = match self.devices.inputs.read() {
            Ok(inputs) => inputs,
            Err(_) => {
                self.device_failed.get_or_insert(Device::Inputs);
                Default::default()
            }
        };
        self.check_device_health();

        // 2. Interlocks (the first trip wins; none are evaluated once stopping).
        if self.trip.is_none() {
            let sense = Sense {
                now_ns: now,
                arm: arm.as_ref(),
                commanded: &self.last_sent.q,
                inputs,
                operator_stop: self.health.operator_stop.load(Ordering::Relaxed),
                recorder_failed: self.health.recorder.as_ref().is_some_and(|r| r.is_failed()),
                device_failed: self.device_failed.or_else(|| self.health.failed_device()),
                check_deviation: true,
            };
            if let Some(kind) = self.interlocks.check(&sense) {
                if let Some(done) = self.begin_trip(kind, k, now) {
                    return done;
                }
            }
        }

        // 3. The setpoint for this tick.
        let (phase, setpoint) = match self.next_setpoint(k, arm.as_ref()) {
            Ok(next) => next,
            Err(outcome) => return Flow::Done(outcome),
        };
        let setpoint = self.correction.apply(k, phase, setpoint);

        // 4. Send it.
        if let Err(e) = self.devices.arm.servo_joint(&setpoint.q) {
            let kind = match e.kind() {
                ErrorKind::DeviceFault | ErrorKind::InvalidRequest => {
                    TripKind::ArmError { code: 0 }
                }
                ErrorKind::Timeout => TripKind::SetpointsUnanswered,
                _ => TripKind::ConnectionLost,
            };
            return self.fail_while_sending(kind, k, now);
        }
        self.last_sent = setpoint;
        self.last_sent_tick = k;

        // 5. Light and captures on the playback schedule.
        if self.trip.is_none() {
            self.schedule_light_and_capture(k, now, &setpoint);
        }

        // 6. Frames the camera has delivered go on to the capture intake.
        match self.devices.camera.poll_frame() {
            Ok(Some(frame)) => self.telemetry.frame(frame),
            Ok(None) => {}
            Err(_) => {
                self.device_failed.get_or_insert(Device::Camera);
            }
        }

        // 7. Telemetry and status.
        self.telemetry.setpoint(&SetpointOut { tick: k, t_ns: now, phase, setpoint });
        let tick_ns = self.clock.now_ns().saturating_sub(now);
        self.telemetry.timing(&TimingOut {
            tick: k,
            t_ns: now,
            wake_late_ns: wake.late_ns,
            tick_ns,
            overrun: wake.overrun,
        });
        self.status.tick.store(k, Ordering::Relaxed);
        self.status.set_phase(phase);
        self.status.max_late_ns.fetch_max(wake.late_ns, Ordering::Relaxed);
        if wake.overrun {
            self.status.overruns.fetch_add(1, Ordering::Relaxed);
        }
        Flow::Continue
    }

    /// Each device's own health (a fault its I/O task tripped), and the trigger lines'
    /// acknowledgements (each fire's time on the trigger device's clock) handed to telemetry.
    fn check_device_health(&mut self) {
        let d = &mut self.devices;
        let failed = if d.light.health().is_err() {
            Some(Device::Light)
        } else if d.camera.health().is_err() {
            Some(Device::Camera)
        } else if d.trigger.health().is_err() {
            Some(Device::Trigger)
        } else {
            None
        };
        if let Some(device) = failed {
            self.device_failed.get_or_insert(device);
        }
        while let Ok(Some(fired)) = self.devices.trigger.poll_fired() {
            self.telemetry.fired(&fired);
        }
    }

    /// Approach, playback, settle or stop: which setpoint tick `k` sends, or the end of the run.
    fn next_setpoint(
        &mut self,
        k: u64,
        arm: Option<&ArmState>,
    ) -> Result<(Phase, JointState), Outcome> {
        let p = self.program;
        if let Some(trip) = self.trip {
            return self.stop_setpoint(k, trip).map(|sp| (Phase::Stop, sp));
        }
        if k < p.approach_ticks() {
            return Ok((Phase::Approach, p.approach[k as usize]));
        }
        if k < p.playback_end() {
            let i = k - p.approach_ticks();
            let phase = if i < p.lead_in_ticks {
                Phase::LeadIn
            } else if i + p.lead_out_ticks >= p.playback.len() as u64 {
                Phase::LeadOut
            } else {
                Phase::Playback
            };
            return Ok((phase, p.playback[i as usize]));
        }
        let settled_on = |goal: &JointState| {
            arm.is_some_and(|a| {
                a.q.iter().zip(goal.q.iter()).all(|(m, c)| (m - c).abs() <= p.settle_tolerance_rad)
            })
        };
        let (from, settled) = match self.retreat_from {
            Some(started) => started,
            None => {
                let goal =
                    p.playback.last().or(p.approach.last()).copied().unwrap_or(self.last_sent);
                let settled = settled_on(&goal);
                let settle_ticks = k - p.playback_end();
                if !settled && settle_ticks < p.settle_max_ticks {
                    let phase = if p.lead_out_ticks > 0 { Phase::LeadOut } else { Phase::Settle };
                    return Ok((phase, JointState::rest(goal.q)));
                }
                if p.retreat.is_empty() {
                    return Err(Outcome::Completed { ticks: k, settled, at_rest: None });
                }
                self.retreat_from = Some((k, settled));
                (k, settled)
            }
        };
        // The retreat, then a settle on its end.
        let i = (k - from) as usize;
        if let Some(sp) = p.retreat.get(i) {
            return Ok((Phase::Retreat, *sp));
        }
        let rest = p.retreat[p.retreat.len() - 1];
        let at_rest = settled_on(&rest);
        if at_rest || (i - p.retreat.len()) as u64 >= p.settle_max_ticks {
            return Err(Outcome::Completed { ticks: k, settled, at_rest: Some(at_rest) });
        }
        Ok((Phase::Retreat, JointState::rest(rest.q)))
    }

    /// The stop's setpoint for tick `k`: from the plan, a bridge until it arrives, or the end.
    fn stop_setpoint(&mut self, k: u64, trip: Trip) -> Result<JointState, Outcome> {
        if self.stop_plan.is_none() {
            self.stop_plan = self.stop.poll();
        }
        match &self.stop_plan {
            Some(plan) if plan.is_empty() => Err(self.hold(trip)),
            Some(plan) => plan.at(k).copied().ok_or(Outcome::Tripped { trip, stopped: true }),
            None if k - trip.tick <= MAX_BRIDGE_TICKS => Ok(self.last_sent.extrapolate(self.dt)),
            None => Err(self.hold(trip)),
        }
    }

    /// Record a trip and start its reaction. Returns the end of the run when it is a hold.
    fn begin_trip(&mut self, kind: TripKind, k: u64, now: u64) -> Option<Flow> {
        let trip = Trip { kind, tick: k, t_ns: now };
        self.trip = Some(trip);
        self.telemetry.trip(&trip);
        self.status.tripped.store(true, Ordering::Relaxed);
        match kind.reaction() {
            Reaction::ControlledStop => {
                self.stop
                    .request(StopRequest { from: self.last_sent, from_tick: self.last_sent_tick });
                None
            }
            Reaction::Hold => Some(Flow::Done(self.hold(trip))),
        }
    }

    /// Tell the arm to stop where it is (if it still hears us) and end the run.
    fn hold(&mut self, trip: Trip) -> Outcome {
        // Send only: the arm's stop is a write that waits for no reply (the xArm driver's `stop`), so the
        // tick never blocks on a box that does not answer. Whether the box really stopped is the
        // stop supervisor's job, after the loop and off this thread (control::stop_supervisor).
        let _ = self.devices.arm.stop();
        Outcome::Tripped { trip, stopped: false }
    }

    /// Sending failed: the first trip if none yet, else the stop in progress ends here.
    fn fail_while_sending(&mut self, kind: TripKind, k: u64, now: u64) -> Flow {
        match self.trip {
            Some(trip) => Flow::Done(Outcome::Tripped { trip, stopped: false }),
            None => {
                let trip = Trip { kind, tick: k, t_ns: now };
                self.trip = Some(trip);
                self.telemetry.trip(&trip);
                self.status.tripped.store(true, Ordering::Relaxed);
                Flow::Done(self.hold(trip))
            }
        }
    }

    /// Apply the light level `light_lead_ticks` early, and fire the camera at capture ticks.
    fn schedule_light_and_capture(&mut self, k: u64, now: u64, commanded: &JointState) {
        let p = self.program;
        let first = p.approach_ticks();
        if let Some(j) = (k + p.light_lead_ticks).checked_sub(first) {
            if let Some(&level) = p.light.get(j as usize) {
                if level != self.light_level {
                    if self.devices.light.set_level(level).is_err() {
                        self.device_failed.get_or_insert(Device::Light);
                    }
                    self.light_level = level;
                    self.telemetry.light(now, level);
                }
            }
        }
        let Some(i) = k.checked_sub(first) else { return };
        if !p.capture.get(i as usize).copied().unwrap_or(false) {
            return;
        }
        // The camera hears of the request before the box pulses its line: a hardware-triggered
        // frame can reach the camera's driver within microseconds of the pulse, and a frame with
        // no request waiting is dropped as stale.
        match self.devices.camera.trigger(CaptureRequest { tick: k, fired_ns: now }) {
            Ok(()) => {}
            // Busy: this capture is lost (and recorded as such), and not pulsed; the camera
            // still works.
            Err(e) if e.kind() == ErrorKind::Timeout => {
                self.telemetry.capture_missed(k, now);
                return;
            }
            Err(_) => {
                self.device_failed.get_or_insert(Device::Camera);
            }
        }
        let lines = TriggerLines { camera: true, light: false };
        if self.devices.trigger.fire(k, lines).is_err() {
            self.device_failed.get_or_insert(Device::Trigger);
        }
        self.telemetry.capture(&CaptureOut {
            tick: k,
            fired_ns: now,
            index: self.captures,
            commanded: *commanded,
            // What the light shows at this exposure (its level went out a lead earlier).
            light_level: p.light_in_effect(k).unwrap_or(f32::NAN),
        });
        self.captures += 1;
        self.status.captures.fetch_add(1, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod light_lead_tests {
    use super::*;

    #[test]
    fn a_capture_sees_the_scheduled_level_once_the_lead_has_passed() {
        let p = Program {
            approach: vec![JointState::rest([0.0; hitl_hal::DOF]); 3],
            light: vec![0.2, 0.2, 0.6, 0.6, 1.0],
            light_lead_ticks: 2,
            ..Program::default()
        };
        // Playback tick i is loop tick 3 + i; its level went out at tick 1 + i.
        assert_eq!(p.light_in_effect(3), Some(0.2));
        assert_eq!(p.light_in_effect(5), Some(0.6));
        assert_eq!(p.light_in_effect(7), Some(1.0));
        assert_eq!(p.light_in_effect(8), None, "after the playback");
        assert_eq!(p.light_in_effect(2), None, "in the approach");
        // A lead longer than the approach: the first captures' levels were never sent in time.
        let long = Program { light_lead_ticks: 4, ..p.clone() };
        assert_eq!(long.light_in_effect(3), None);
        assert_eq!(long.light_in_effect(4), Some(0.2));
        assert_eq!(Program::default().light_in_effect(0), None, "no schedule");
    }
}
