//! What the tick hands out, and the status the progress display reads: the contract between the
//! control loop (the producer) and everything downstream of it (the capture path, the recorder,
//! the progress line). Neither side imports the other; both import this.
//!
//! [`trip`] holds the facts of a trip (what and when); what a trip means for motion and for the
//! exit code is the interlocks' business (`control::interlocks`).
//!
//! The tick calls a [`TelemetrySink`] with small `Copy` messages; a sink must never block or
//! allocate (bounded lock-free queues that drop and count when full). [`LoopStatus`] is a set of
//! atomics for the operator's progress line.

mod trip;

pub use trip::{Device, Trip, TripKind};

use hitl_hal::{ArmState, FireReport, RgbdFrame};
use hitl_hal::{JointState, Phase};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};

/// `/arm/setpoint`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetpointOut {
    pub tick: u64,
    pub t_ns: u64,
    pub phase: Phase,
    pub setpoint: JointState,
}

/// `/loop/timing`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimingOut {
    pub tick: u64,
    pub t_ns: u64,
    pub wake_late_ns: u64,
    pub tick_ns: u64,
    pub overrun: bool,
}

/// A capture fired by the tick (camera trigger), with the light level at that moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureOut {
    pub tick: u64,
    pub fired_ns: u64,
    /// Index of the capture in the run (0, 1, ...).
    pub index: u32,
    /// The setpoint commanded at the capture tick.
    pub commanded: JointState,
    pub light_level: f32,
}

/// Where the tick's telemetry goes. Implementations must not block or allocate.
pub trait TelemetrySink {
    fn setpoint(&self, m: &SetpointOut);
    fn timing(&self, m: &TimingOut);
    fn arm_state(&self, s: &ArmState);
    fn light(&self, t_ns: u64, level: f32);
    fn capture(&self, c: &CaptureOut);
    fn trip(&self, trip: &Trip);
    /// A capture the camera could not take now (busy): recorded as a capture not recorded.
    fn capture_missed(&self, tick: u64, t_ns: u64);
    /// A frame the camera delivered: moved on (never copied) to the capture intake.
    fn frame(&self, frame: RgbdFrame);
    /// A trigger-line fire the trigger device acknowledged, with its own fire time.
    fn fired(&self, f: &FireReport);
}

/// A sink that keeps nothing (runs without a recording still count ticks in [`LoopStatus`]).
#[derive(Debug, Default, Clone, Copy)]
pub struct NoTelemetry;

impl TelemetrySink for NoTelemetry {
    fn setpoint(&self, _: &SetpointOut) {}
    fn timing(&self, _: &TimingOut) {}
    fn arm_state(&self, _: &ArmState) {}
    fn light(&self, _: u64, _: f32) {}
    fn capture(&self, _: &CaptureOut) {}
    fn trip(&self, _: &Trip) {}
    fn capture_missed(&self, _: u64, _: u64) {}
    fn frame(&self, _: RgbdFrame) {}
    fn fired(&self, _: &FireReport) {}
}

/// Live status of the loop for the progress line (atomics; written by the tick).
#[derive(Debug, Default)]
pub struct LoopStatus {
    pub tick: AtomicU64,
    pub phase: AtomicU8,
    pub tripped: AtomicBool,
    pub overruns: AtomicU64,
    pub max_late_ns: AtomicU64,
    pub captures: AtomicU64,
    pub done: AtomicBool,
}

impl LoopStatus {
    pub fn set_phase(&self, phase: Phase) {
        self.phase.store(phase as u8, Ordering::Relaxed);
    }

    pub fn phase(&self) -> Phase {
        match self.phase.load(Ordering::Relaxed) {
            0 => Phase::Approach,
            1 => Phase::Playback,
            2 => Phase::Settle,
            4 => Phase::LeadIn,
            5 => Phase::LeadOut,
            6 => Phase::Retreat,
            _ => Phase::Stop,
        }
    }
}
