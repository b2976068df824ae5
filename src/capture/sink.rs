//! The tick's telemetry sink for a run: recorder queues (when recording) and the capture intake's
//! queues. Every method is a lock-free push that never blocks or allocates; full queues drop and
//! count (the recorder's telemetry drops its oldest, frames are counted as lost and reported).
//! A lost frame is not dropped here, which would free its image buffers on the loop thread: it
//! goes to the discard queue, and the intake thread frees it.

use crate::telemetry::{CaptureOut, SetpointOut, TelemetrySink, TimingOut};
use crate::telemetry::{Trip, TripKind};
use crossbeam::queue::ArrayQueue;
use hitl_hal::{ArmState, FireReport, RgbdFrame, Trigger};
use hitl_record::{
    ArmStateMsg, EventKind, LightMsg, SafetyEventMsg, SetpointMsg, Telemetry, TimingMsg,
    TriggerFiredMsg,
};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Queues from the tick to the capture intake.
#[derive(Debug)]
pub struct IntakeQueues {
    pub frames: ArrayQueue<RgbdFrame>,
    pub states: ArrayQueue<ArmState>,
    pub captures: ArrayQueue<CaptureOut>,
    /// Frames handed over by the camera (queued or lost).
    pub frames_in: AtomicU64,
    /// Frames the intake has finished with (recorded or not, handed to perception).
    pub frames_done: AtomicU64,
    /// Captures the camera was too busy to take.
    pub captures_missed: AtomicU64,
    /// Frames that found the intake queue full.
    pub frames_lost: AtomicU64,
    /// Lost frames on their way to be freed by the intake thread, not by the tick.
    pub discard: ArrayQueue<RgbdFrame>,
    /// Lost frames that found the discard queue full too (the intake thread has not run for
    /// `frames + discard` frames): leaked rather than freed on the loop thread.
    pub frames_leaked: AtomicU64,
}

impl IntakeQueues {
    pub fn new() -> Self {
        Self {
            frames: ArrayQueue::new(16),
            states: ArrayQueue::new(4096),
            captures: ArrayQueue::new(256),
            frames_in: AtomicU64::new(0),
            frames_done: AtomicU64::new(0),
            captures_missed: AtomicU64::new(0),
            frames_lost: AtomicU64::new(0),
            discard: ArrayQueue::new(64),
            frames_leaked: AtomicU64::new(0),
        }
    }
}

impl Default for IntakeQueues {
    fn default() -> Self {
        Self::new()
    }
}

/// The sink a run's tick writes to.
pub struct RunTelemetry {
    pub record: Option<Telemetry>,
    pub intake: Arc<IntakeQueues>,
}

/// The recorder's event for a trip, with its numbers (no text: the tick cannot format).
fn trip_event(trip: &Trip) -> SafetyEventMsg {
    let (kind, joint, value, limit) = match trip.kind {
        TripKind::ReportWatchdog { silent_ms } => (EventKind::ReportWatchdog, None, silent_ms, 0.0),
        TripKind::ConnectionLost | TripKind::SetpointsUnanswered => {
            (EventKind::DeviceFault, None, 0.0, 0.0)
        }
        TripKind::ArmError { code } => (EventKind::ArmError, None, f64::from(code), 0.0),
        TripKind::ArmWarning { code } => (EventKind::ArmWarning, None, f64::from(code), 0.0),
        TripKind::Deviation { joint, deviation_rad } => {
            (EventKind::Deviation, Some(joint as u8 + 1), deviation_rad, 0.0)
        }
        TripKind::EStop => (EventKind::EStop, None, 1.0, 0.0),
        TripKind::DoorOpen => (EventKind::DoorOpen, None, 1.0, 0.0),
        TripKind::OperatorStop => (EventKind::OperatorStop, None, 1.0, 0.0),
        TripKind::RecorderFailed => (EventKind::RecorderFailed, None, 1.0, 0.0),
        TripKind::DeviceFailed { device } => {
            (EventKind::DeviceFault, None, device as u8 as f64, 0.0)
        }
    };
    SafetyEventMsg::numeric(trip.t_ns, kind, trip.tick, joint, value, limit)
}

impl RunTelemetry {
    /// After the loop, once the devices have stopped (the trigger box's stop waits for the
    /// answers to what it sent): the fires answered after the loop's last tick, recorded like the
    /// others. The last capture's pulse is answered a few milliseconds after its tick, which may
    /// be the run's last.
    pub fn record_late_fires<T: Trigger + ?Sized>(&self, trigger: &mut T) {
        while let Ok(Some(fired)) = trigger.poll_fired() {
            self.fired(&fired);
        }
    }
}

impl TelemetrySink for RunTelemetry {
    fn setpoint(&self, m: &SetpointOut) {
        if let Some(r) = &self.record {
            r.push_setpoint(&SetpointMsg {
                tick: m.tick,
                t_ns: m.t_ns,
                phase: m.phase.recorded(),
                q: m.setpoint.q,
                qd: m.setpoint.qd,
            });
        }
    }

    fn timing(&self, m: &TimingOut) {
        if let Some(r) = &self.record {
            r.push_timing(&TimingMsg {
                tick: m.tick,
                t_ns: m.t_ns,
                wake_late_ns: m.wake_late_ns as i64,
                tick_ns: m.tick_ns,
                overrun: m.overrun,
            });
        }
    }

    fn arm_state(&self, s: &ArmState) {
        if let Some(r) = &self.record {
            r.push_state(&ArmStateMsg::from(s));
        }
        let _ = self.intake.states.force_push(*s);
    }

    fn light(&self, t_ns: u64, level: f32) {
        if let Some(r) = &self.record {
            r.push_light(&LightMsg { t_ns, level });
        }
    }

    fn fired(&self, f: &FireReport) {
        if let Some(r) = &self.record {
            r.push_fired(&TriggerFiredMsg {
                t_ns: f.acked_ns,
                tick: f.tick,
                device_us: f.device_us,
                fired_ns: f.host_ns,
                clock_error_ns: f.host_error_ns,
            });
        }
    }

    fn capture(&self, c: &CaptureOut) {
        let _ = self.intake.captures.force_push(*c);
    }

    fn trip(&self, trip: &Trip) {
        if let Some(r) = &self.record {
            r.push_event(trip_event(trip));
        }
    }

    fn capture_missed(&self, tick: u64, t_ns: u64) {
        if let Some(r) = &self.record {
            r.push_event(SafetyEventMsg::numeric(
                t_ns,
                EventKind::CaptureNotRecorded,
                tick,
                None,
                0.0,
                0.0,
            ));
        }
        self.intake.captures_missed.fetch_add(1, Ordering::Relaxed);
    }

    fn frame(&self, frame: RgbdFrame) {
        self.intake.frames_in.fetch_add(1, Ordering::Relaxed);
        if let Err(frame) = self.intake.frames.push(frame) {
            self.intake.frames_lost.fetch_add(1, Ordering::Relaxed);
            // Dropping it here would free its buffers on the loop thread: the intake frees it.
            if let Err(frame) = self.intake.discard.push(frame) {
                // The intake thread has not run for 80 frames (seconds at camera rates): leaking
                // one frame is the lesser harm than a free on the loop thread. Counted.
                self.intake.frames_leaked.fetch_add(1, Ordering::Relaxed);
                std::mem::forget(frame);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_hal::{CaptureRequest, Intrinsics, TimestampSource};

    fn frame(tick: u64) -> RgbdFrame {
        RgbdFrame {
            request: CaptureRequest { tick, fired_ns: 0 },
            device_ns: 0,
            exposure_ns: 0,
            timestamp: TimestampSource::HostArrival,
            intrinsics: Intrinsics::pinhole(2, 2, 1.0, 1.0, 1.0, 1.0),
            color: vec![7; 12].into(),
            depth_m: vec![1.0; 4].into(),
            mask: None,
        }
    }

    #[test]
    fn a_frame_that_finds_the_intake_full_is_handed_over_not_freed() {
        let intake = Arc::new(IntakeQueues::new());
        let sink = RunTelemetry { record: None, intake: Arc::clone(&intake) };
        for k in 0..16 {
            sink.frame(frame(k));
        }
        assert_eq!(intake.frames.len(), 16);
        let lost = frame(16);
        let buffer = lost.color.as_ptr();
        sink.frame(lost);
        assert_eq!(intake.frames_lost.load(Ordering::Relaxed), 1);
        // The very buffer is in the discard queue: the sink freed nothing.
        let handed = intake.discard.pop().expect("handed over");
        assert_eq!(handed.request.tick, 16);
        assert_eq!(handed.color.as_ptr(), buffer);
        assert_eq!(intake.frames_leaked.load(Ordering::Relaxed), 0);
    }
}
