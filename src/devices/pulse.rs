//! A hardware-triggered camera's exposure at its trigger pulse. The trigger box reports when it
//! raised the camera line on its own clock, and its driver maps that onto the host's clock (with a
//! bound on the error, recorded on `/trigger/fired`); a camera whose sync input that line drives
//! starts its exposure at the pulse. So the frame of tick `k` gets the pulse of tick `k` as its
//! exposure time, rather than the camera's own stamp (an arrival time, or the camera's clock
//! fitted by its SDK).
//!
//! [`RecordFires`] wraps the run's trigger and keeps the mapped fire time of recent ticks in a
//! [`FireTimes`] table; [`PulseExposure`] wraps the camera and looks its frames' ticks up there.
//! Both run on the tick (lock-free, no allocation). A frame whose fire is not known (not yet
//! acknowledged, or the box's clock not mapped) keeps the camera's stamp.

use super::any::{CameraDevice, Faulted, TriggerDevice};
use hitl_hal::{
    CaptureRequest, ErrorKind, ErrorType, FireReport, Intrinsics, Lifecycle, RgbdCamera, RgbdFrame,
    StreamConfig, TimestampSource, Trigger, TriggerLines,
};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Ticks remembered (the newest fire of each tick modulo this).
const SLOTS: usize = 256;
const EMPTY: u64 = u64::MAX;

/// The mapped fire time of recent ticks.
pub struct FireTimes {
    ticks: [AtomicU64; SLOTS],
    host_ns: [AtomicU64; SLOTS],
}

impl Default for FireTimes {
    fn default() -> Self {
        Self {
            ticks: std::array::from_fn(|_| AtomicU64::new(EMPTY)),
            host_ns: std::array::from_fn(|_| AtomicU64::new(0)),
        }
    }
}

impl FireTimes {
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
    }

    fn record(&self, tick: u64, host_ns: u64) {
        let i = (tick % SLOTS as u64) as usize;
        self.ticks[i].store(EMPTY, Ordering::Release);
        self.host_ns[i].store(host_ns, Ordering::Release);
        self.ticks[i].store(tick, Ordering::Release);
    }

    /// The host time tick `tick` fired at, if known.
    pub fn get(&self, tick: u64) -> Option<u64> {
        let i = (tick % SLOTS as u64) as usize;
        (self.ticks[i].load(Ordering::Acquire) == tick)
            .then(|| self.host_ns[i].load(Ordering::Acquire))
    }
}

/// The run's trigger, remembering each acknowledged fire's host time.
pub struct RecordFires {
    pub inner: Box<dyn TriggerDevice>,
    pub times: Arc<FireTimes>,
}

impl ErrorType for RecordFires {
    type Error = ErrorKind;
}

impl Lifecycle for RecordFires {
    fn start(&mut self) -> Result<(), ErrorKind> {
        self.inner.start()
    }
    fn health(&mut self) -> Result<(), ErrorKind> {
        self.inner.health()
    }
    fn stop(&mut self) -> Result<(), ErrorKind> {
        self.inner.stop()
    }
}

impl Faulted for RecordFires {
    fn fault_text(&self) -> Option<String> {
        self.inner.fault_text()
    }
}

impl Trigger for RecordFires {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), ErrorKind> {
        self.inner.fire(tick, lines)
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, ErrorKind> {
        let r = self.inner.poll_fired()?;
        if let Some(FireReport { tick, host_ns: Some(host), .. }) = r {
            self.times.record(tick, host);
        }
        Ok(r)
    }
}

/// The run's camera, its frames' exposure at their trigger pulse.
pub struct PulseExposure {
    pub inner: Box<dyn CameraDevice>,
    pub times: Arc<FireTimes>,
}

impl ErrorType for PulseExposure {
    type Error = ErrorKind;
}

impl Lifecycle for PulseExposure {
    fn start(&mut self) -> Result<(), ErrorKind> {
        self.inner.start()
    }
    fn health(&mut self) -> Result<(), ErrorKind> {
        self.inner.health()
    }
    fn stop(&mut self) -> Result<(), ErrorKind> {
        self.inner.stop()
    }
}

impl Faulted for PulseExposure {
    fn fault_text(&self) -> Option<String> {
        self.inner.fault_text()
    }
}

impl RgbdCamera for PulseExposure {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
        self.inner.configure(config)
    }
    fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
        self.inner.arm_trigger()
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), ErrorKind> {
        self.inner.trigger(request)
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
        let mut frame = self.inner.poll_frame()?;
        if let Some(f) = frame.as_mut() {
            if let Some(host) = self.times.get(f.request.tick) {
                f.exposure_ns = host;
                f.timestamp = TimestampSource::DeviceExposure;
            }
        }
        Ok(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::any::Kinds;

    struct OneFire(Option<FireReport>);
    impl ErrorType for OneFire {
        type Error = ErrorKind;
    }
    impl Lifecycle for OneFire {}
    impl Trigger for OneFire {
        fn fire(&mut self, _: u64, _: TriggerLines) -> Result<(), ErrorKind> {
            Ok(())
        }
        fn poll_fired(&mut self) -> Result<Option<FireReport>, ErrorKind> {
            Ok(self.0.take())
        }
    }

    struct Frames(Vec<RgbdFrame>);
    impl ErrorType for Frames {
        type Error = ErrorKind;
    }
    impl Lifecycle for Frames {}
    impl RgbdCamera for Frames {
        fn configure(&mut self, c: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
            Ok(c.intrinsics)
        }
        fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
            Ok(())
        }
        fn trigger(&mut self, _: CaptureRequest) -> Result<(), ErrorKind> {
            Ok(())
        }
        fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
            Ok(self.0.pop())
        }
    }

    fn frame(tick: u64, exposure_ns: u64) -> RgbdFrame {
        RgbdFrame {
            request: CaptureRequest { tick, fired_ns: 1_000 },
            device_ns: 7,
            exposure_ns,
            timestamp: TimestampSource::HostArrival,
            intrinsics: Intrinsics::pinhole(1, 1, 1.0, 1.0, 0.0, 0.0),
            color: vec![0; 3].into(),
            depth_m: vec![0.0].into(),
            mask: None,
        }
    }

    #[test]
    fn a_frame_takes_its_ticks_pulse_as_its_exposure() {
        let times = FireTimes::new();
        let fire = FireReport {
            tick: 40,
            device_us: 5,
            acked_ns: 9_000,
            host_ns: Some(2_500),
            host_error_ns: Some(300),
        };
        let mut trigger = RecordFires {
            inner: Box::new(Kinds::new(OneFire(Some(fire)))),
            times: Arc::clone(&times),
        };
        let mut camera = PulseExposure {
            inner: Box::new(Kinds::new(Frames(vec![frame(41, 8_000), frame(40, 8_000)]))),
            times,
        };
        assert_eq!(trigger.poll_fired(), Ok(Some(fire)));
        let f = camera.poll_frame().expect("ok").expect("frame of tick 40");
        assert_eq!((f.exposure_ns, f.timestamp), (2_500, TimestampSource::DeviceExposure));
        // No fire known for tick 41: the camera's own stamp stays.
        let f = camera.poll_frame().expect("ok").expect("frame of tick 41");
        assert_eq!((f.exposure_ns, f.timestamp), (8_000, TimestampSource::HostArrival));
    }

    #[test]
    fn the_table_forgets_a_tick_overwritten_by_a_later_one() {
        let t = FireTimes::default();
        t.record(3, 30);
        assert_eq!(t.get(3), Some(30));
        t.record(3 + SLOTS as u64, 40);
        assert_eq!(t.get(3), None);
        assert_eq!(t.get(3 + SLOTS as u64), Some(40));
        assert_eq!(t.get(4), None);
    }
}
