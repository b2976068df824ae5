//! The trigger box's clock on the host's: offset and drift fitted over the round trips of the
//! box's answers, with a bound on the mapping's error (docs/trigger-box-protocol.md, "Host side").
//!
//! Every answered command (`A`, `V`) is one sample: the box stamped its answer with `device_us`
//! somewhere between the command's last byte reaching it and its answer's first byte leaving it.
//! On the host's clock that instant lies in `[sent + (command bytes - 1) * byte time, received -
//! (answer bytes - 1) * byte time]`: the bytes of a line cannot cross the UART between the box
//! and its USB chip faster than the baud rate allows. (One byte of each line is left out of the
//! bound: the box takes a byte when its stop bit is half done, and box-sim passes a byte on when
//! it starts.) The sample's midpoint is the estimate, its half-width the bound.
//!
//! [`ClockFit`] keeps the recent samples and fits `host - device` as a straight line of device
//! time, weighted by the inverse square of each half-width, which gives the offset and the drift
//! of the box's oscillator against the host's clock (a ceramic resonator is off by up to 0.5 %).
//! The error of the mapping at a device time `d` is bounded by the best sample: its half-width,
//! plus how far the line passes from its midpoint, plus the drift's uncertainty times the distance
//! from it. [`MappingCell`] hands the newest fit to the tick without locks.

use std::collections::VecDeque;
use std::sync::atomic::{fence, AtomicU64, Ordering};

/// Drift assumed before it can be fitted (and the largest believed): 0.5 %, a ceramic
/// resonator's tolerance (an Arduino Uno's); a crystal is within 0.01 %.
pub const DRIFT_PRIOR: f64 = 5e-3;
/// Drift is fitted only over samples spanning at least this much device time (ns).
const MIN_DRIFT_SPAN_NS: f64 = 500e6;
/// Samples older than this (device time, ns) before the newest are dropped.
const WINDOW_NS: u64 = 30_000_000_000;
/// Samples kept at most.
const MAX_SAMPLES: usize = 128;
/// A half-width below this is taken as this for the weights (ns): the host's clock reading and
/// the box's stamp resolution (1 us) are not better.
const MIN_HALF_WIDTH_NS: f64 = 1_000.0;
/// The drift's uncertainty is never taken below this (1 ppm).
const MIN_DRIFT_ERR: f64 = 1e-6;

/// One answered command: the box's stamp and the host-time interval it must lie in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    pub device_ns: u64,
    pub host_lo_ns: u64,
    pub host_hi_ns: u64,
}

impl Sample {
    /// The sample for an answer stamped `device_us`, for a command of `command_bytes` (with its
    /// `\n`) whose write began at `sent_ns`, and an answer of `answer_bytes` (with its `\n`)
    /// taken in at `received_ns`; `byte_ns` is one byte's time on the box's UART. Where the bytes'
    /// time does not fit the round trip (a link faster than assumed), the round trip alone.
    pub fn new(
        device_us: u64,
        sent_ns: u64,
        command_bytes: usize,
        received_ns: u64,
        answer_bytes: usize,
        byte_ns: u64,
    ) -> Option<Self> {
        if received_ns < sent_ns {
            return None;
        }
        let wire = |n: usize| (n.saturating_sub(1) as u64).saturating_mul(byte_ns);
        let lo = sent_ns.saturating_add(wire(command_bytes));
        let hi = received_ns.saturating_sub(wire(answer_bytes));
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (sent_ns, received_ns) };
        Some(Self { device_ns: device_us.saturating_mul(1000), host_lo_ns: lo, host_hi_ns: hi })
    }

    /// An estimate of this sample's stamp on the host's clock (`host_ns`, within `error_ns`, from
    /// the fit) held to the sample's own interval, where the stamp must be: the fit's estimate
    /// where it falls inside (its bound no wider than the interval allows), else the nearest end
    /// of the interval, known to the interval's width. (A clock that is not a straight line over
    /// the fit's window, which box-sim's is not when it falls behind the wall clock, can put the
    /// line outside; a real box's oscillator does not.)
    pub fn hold(&self, host_ns: u64, error_ns: u64) -> (u64, u64) {
        let held = host_ns.clamp(self.host_lo_ns, self.host_hi_ns);
        let own = (held - self.host_lo_ns).max(self.host_hi_ns - held);
        if held == host_ns {
            (held, error_ns.min(own))
        } else {
            (held, own)
        }
    }

    fn mid(&self) -> f64 {
        (self.host_lo_ns as f64 + self.host_hi_ns as f64) / 2.0
    }

    fn half_width(&self) -> f64 {
        (self.host_hi_ns - self.host_lo_ns) as f64 / 2.0
    }
}

/// The box's clock on the host's: `host = device + offset(device)`, a straight line through a
/// reference point; and the error bound around it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mapping {
    /// Reference point: a device time (ns) and its host time (ns).
    pub ref_device_ns: u64,
    pub ref_host_ns: u64,
    /// Host ns per device ns, minus 1 (the box's clock is slow when positive).
    pub drift: f64,
    /// The drift's uncertainty (same unit).
    pub drift_err: f64,
    /// The sample with the smallest bound: its device time and bound (ns).
    pub best_device_ns: u64,
    pub best_err_ns: f64,
    /// The newest sample: its device time and bound (ns).
    pub newest_device_ns: u64,
    pub newest_err_ns: f64,
    /// Samples in the fit.
    pub samples: u32,
}

impl Mapping {
    /// The box's `device_us` on the host's clock, ns.
    pub fn host_ns(&self, device_us: u64) -> u64 {
        let d = device_us.saturating_mul(1000);
        let dx = d as i128 - self.ref_device_ns as i128;
        let host = self.ref_host_ns as i128 + dx + (dx as f64 * self.drift).round() as i128;
        u64::try_from(host.max(0)).unwrap_or(u64::MAX)
    }

    /// The host's `host_ns` on the box's clock, us (the inverse of [`Mapping::host_ns`]).
    pub fn device_us(&self, host_ns: u64) -> u64 {
        let dh = host_ns as i128 - self.ref_host_ns as i128;
        let dx = dh as f64 / (1.0 + self.drift);
        let d = self.ref_device_ns as f64 + dx;
        (d / 1000.0).round().max(0.0) as u64
    }

    /// A bound on [`Mapping::host_ns`]'s error at `device_us`, ns (from the best and the newest
    /// sample; [`ClockFit::error_ns`] looks at every sample).
    pub fn error_ns(&self, device_us: u64) -> u64 {
        let d = device_us.saturating_mul(1000) as f64;
        let from = |at: u64, err: f64| err + (d - at as f64).abs() * self.drift_err;
        from(self.best_device_ns, self.best_err_ns)
            .min(from(self.newest_device_ns, self.newest_err_ns))
            .ceil() as u64
    }
}

/// The recent samples and the line fitted through them.
#[derive(Debug, Default)]
pub struct ClockFit {
    samples: VecDeque<Sample>,
    mapping: Option<Mapping>,
    /// Each sample's bound against the current fit (half-width + |residual|), by index.
    bounds: Vec<f64>,
}

impl ClockFit {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn mapping(&self) -> Option<Mapping> {
        self.mapping
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Forget every sample (the box restarted: its clock began again).
    pub fn clear(&mut self) {
        self.samples.clear();
        self.bounds.clear();
        self.mapping = None;
    }

    /// Add a sample and fit again; the new mapping.
    pub fn add(&mut self, s: Sample) -> Option<Mapping> {
        // A stamp older than the newest one: the box's clock went back (a restart, which the
        // banner reports) or the sample is wrong; start over from it.
        if self.samples.back().is_some_and(|b| s.device_ns < b.device_ns) {
            self.clear();
        }
        self.samples.push_back(s);
        while self.samples.len() > MAX_SAMPLES
            || self.samples.front().is_some_and(|f| s.device_ns - f.device_ns > WINDOW_NS)
        {
            self.samples.pop_front();
        }
        self.refit();
        self.mapping
    }

    fn refit(&mut self) {
        let Some(newest) = self.samples.back().copied() else {
            self.mapping = None;
            return;
        };
        // Numbers relative to the newest sample, so that f64 keeps nanoseconds.
        let d0 = newest.device_ns;
        let c0 = newest.mid() - d0 as f64;
        let pts: Vec<(f64, f64, f64)> = self
            .samples
            .iter()
            .map(|s| {
                let x = s.device_ns as f64 - d0 as f64;
                let y = (s.mid() - s.device_ns as f64) - c0;
                let w = 1.0 / s.half_width().max(MIN_HALF_WIDTH_NS).powi(2);
                (x, y, w)
            })
            .collect();
        let sw: f64 = pts.iter().map(|p| p.2).sum();
        let xm = pts.iter().map(|p| p.0 * p.2).sum::<f64>() / sw;
        let ym = pts.iter().map(|p| p.1 * p.2).sum::<f64>() / sw;
        let sxx: f64 = pts.iter().map(|p| p.2 * (p.0 - xm).powi(2)).sum();
        let span = pts.iter().map(|p| p.0).fold(0.0f64, |a, x| a.max(-x));
        let (drift, drift_err) = if pts.len() >= 3 && span >= MIN_DRIFT_SPAN_NS && sxx > 0.0 {
            let sxy: f64 = pts.iter().map(|p| p.2 * (p.0 - xm) * (p.1 - ym)).sum();
            let b = (sxy / sxx).clamp(-DRIFT_PRIOR, DRIFT_PRIOR);
            // Each half-width taken as one standard deviation (a bound is wider than that).
            let sigma = (1.0 / sxx).sqrt();
            (b, (3.0 * sigma + MIN_DRIFT_ERR).min(DRIFT_PRIOR))
        } else {
            (0.0, DRIFT_PRIOR)
        };
        // The line through the weighted centroid: offset at x = 0 (the newest sample).
        let a = ym - drift * xm;
        let line = |x: f64| a + drift * x;
        self.bounds = self
            .samples
            .iter()
            .zip(&pts)
            .map(|(s, p)| s.half_width() + (p.1 - line(p.0)).abs())
            .collect();
        let (best_i, best_err) = self
            .bounds
            .iter()
            .copied()
            .enumerate()
            .fold((0, f64::INFINITY), |acc, (i, b)| if b < acc.1 { (i, b) } else { acc });
        let ref_host = d0 as f64 + c0 + a;
        self.mapping = Some(Mapping {
            ref_device_ns: d0,
            ref_host_ns: ref_host.round().max(0.0) as u64,
            drift,
            drift_err,
            best_device_ns: self.samples[best_i].device_ns,
            best_err_ns: best_err,
            newest_device_ns: d0,
            newest_err_ns: self.bounds.last().copied().unwrap_or(f64::INFINITY),
            samples: u32::try_from(self.samples.len()).unwrap_or(u32::MAX),
        });
    }

    /// The bound on the mapping's error at `device_us` over every sample, ns.
    pub fn error_ns(&self, device_us: u64) -> Option<u64> {
        let m = self.mapping?;
        let d = device_us.saturating_mul(1000) as f64;
        let e = self
            .samples
            .iter()
            .zip(&self.bounds)
            .map(|(s, b)| b + (d - s.device_ns as f64).abs() * m.drift_err)
            .fold(f64::INFINITY, f64::min);
        Some(e.ceil() as u64)
    }
}

/// A [`Mapping`] shared between the I/O task (one writer) and the tick (readers) without locks:
/// a sequence lock over atomic words (a reader retries while a write is under way; the writer
/// never waits).
#[derive(Debug)]
pub struct MappingCell {
    seq: AtomicU64,
    words: [AtomicU64; 10],
}

impl Default for MappingCell {
    fn default() -> Self {
        Self::new()
    }
}

impl MappingCell {
    pub fn new() -> Self {
        Self { seq: AtomicU64::new(0), words: std::array::from_fn(|_| AtomicU64::new(0)) }
    }

    /// Publish `m` (one writer at a time: the box's task).
    pub fn store(&self, m: &Mapping) {
        let words = [
            1,
            m.ref_device_ns,
            m.ref_host_ns,
            m.drift.to_bits(),
            m.drift_err.to_bits(),
            m.best_device_ns,
            m.best_err_ns.to_bits(),
            m.newest_device_ns,
            m.newest_err_ns.to_bits(),
            u64::from(m.samples),
        ];
        let s = self.seq.load(Ordering::Relaxed);
        self.seq.store(s.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (w, v) in self.words.iter().zip(words) {
            w.store(v, Ordering::Relaxed);
        }
        self.seq.store(s.wrapping_add(2), Ordering::Release);
    }

    /// The latest mapping, if one was published. Never blocks the writer; never allocates.
    pub fn load(&self) -> Option<Mapping> {
        loop {
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let w: [u64; 10] = std::array::from_fn(|i| self.words[i].load(Ordering::Relaxed));
            fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) != s1 {
                continue;
            }
            if w[0] == 0 {
                return None;
            }
            return Some(Mapping {
                ref_device_ns: w[1],
                ref_host_ns: w[2],
                drift: f64::from_bits(w[3]),
                drift_err: f64::from_bits(w[4]),
                best_device_ns: w[5],
                best_err_ns: f64::from_bits(w[6]),
                newest_device_ns: w[7],
                newest_err_ns: f64::from_bits(w[8]),
                samples: u32::try_from(w[9]).unwrap_or(u32::MAX),
            });
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A box whose clock runs `drift` slow against the host and started at host `epoch_ns`;
    /// a round trip of `rtt_ns` whose stamp falls `at` of the way through it.
    fn sample(host_stamp_ns: u64, epoch_ns: u64, drift: f64, rtt_ns: u64, at: f64) -> Sample {
        let device_ns = ((host_stamp_ns - epoch_ns) as f64 / (1.0 + drift)) as u64;
        let sent = host_stamp_ns - (rtt_ns as f64 * at) as u64;
        let received = sent + rtt_ns;
        Sample::new(device_ns / 1000, sent, 1, received, 1, 0).unwrap()
    }

    #[test]
    fn a_sample_is_the_round_trip_less_the_bytes_on_the_wire() {
        // "P 12\n" (5 bytes) and "A 12 3456789\n" (13) at 86.8 us a byte.
        let s = Sample::new(3_456_789, 1_000_000, 5, 3_500_000, 13, 86_806).unwrap();
        assert_eq!(s.host_lo_ns, 1_000_000 + 4 * 86_806);
        assert_eq!(s.host_hi_ns, 3_500_000 - 12 * 86_806);
        assert_eq!(s.device_ns, 3_456_789_000);
        // Bytes that do not fit the round trip: the round trip alone.
        let s = Sample::new(1, 1_000, 5, 2_000, 13, 86_806).unwrap();
        assert_eq!((s.host_lo_ns, s.host_hi_ns), (1_000, 2_000));
        assert!(Sample::new(1, 2_000, 5, 1_000, 13, 0).is_none());
    }

    #[test]
    fn an_estimate_is_held_to_its_own_round_trip() {
        let s = Sample { device_ns: 0, host_lo_ns: 1_000, host_hi_ns: 3_000 };
        // Inside: the fit's estimate, its bound no wider than the interval allows.
        assert_eq!(s.hold(1_500, 100), (1_500, 100));
        assert_eq!(s.hold(1_500, 5_000), (1_500, 1_500));
        // Outside: the nearest end, known to the interval's width.
        assert_eq!(s.hold(3_700, 50), (3_000, 2_000));
        assert_eq!(s.hold(10, 50), (1_000, 2_000));
    }

    #[test]
    fn one_sample_maps_through_its_midpoint_with_its_half_width() {
        let mut fit = ClockFit::new();
        let m =
            fit.add(Sample { device_ns: 5_000_000, host_lo_ns: 9_000_000, host_hi_ns: 9_200_000 });
        let m = m.unwrap();
        assert_eq!(m.host_ns(5_000), 9_100_000);
        assert_eq!(m.error_ns(5_000), 100_000);
        // 1 ms away the prior drift (0.5 %) widens it by 5 us.
        assert_eq!(m.error_ns(6_000), 105_000);
        assert_eq!(fit.error_ns(6_000), Some(105_000));
        assert_eq!(m.device_us(m.host_ns(6_000)), 6_000);
    }

    #[test]
    fn drift_and_offset_are_fitted_within_the_bound() {
        // 200 ppm slow, started at host 1 s; round trips of 2 ms with the stamp anywhere in them.
        let (epoch, drift) = (1_000_000_000u64, 200e-6);
        let mut fit = ClockFit::new();
        let mut rng = 12345u64;
        let mut m = None;
        for i in 0..40u64 {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let at = (rng >> 33) as f64 / (1u64 << 31) as f64;
            m = fit.add(sample(epoch + 10_000_000 + i * 250_000_000, epoch, drift, 2_000_000, at));
        }
        let m = m.unwrap();
        assert!((m.drift - drift).abs() < m.drift_err, "drift {} +- {}", m.drift, m.drift_err);
        // 1 ms round trips over 10 s: the drift to a few tens of ppm (3 sigma, each half-width
        // taken as a standard deviation).
        assert!(m.drift_err < 200e-6, "drift known to {}", m.drift_err);
        // Anywhere in the span, and 1 s past it, the truth is within the bound.
        for host in [epoch + 20_000_000, epoch + 5_000_000_000, epoch + 10_900_000_000] {
            let device_us = ((host - epoch) as f64 / (1.0 + drift) / 1000.0) as u64;
            let truth = epoch as f64 + device_us as f64 * 1000.0 * (1.0 + drift);
            let err = (m.host_ns(device_us) as f64 - truth).abs();
            let bound = fit.error_ns(device_us).unwrap() as f64;
            assert!(err <= bound, "at {host}: error {err} ns, bound {bound} ns");
            assert!(bound <= m.error_ns(device_us) as f64 + 1.0);
            // A half-width of 1 ms, the line within a millisecond of the midpoints.
            assert!(bound < 2_500_000.0, "bound {bound}");
        }
    }

    #[test]
    fn a_clock_that_goes_back_starts_the_fit_again() {
        let mut fit = ClockFit::new();
        fit.add(Sample { device_ns: 9_000_000_000, host_lo_ns: 10, host_hi_ns: 20 });
        fit.add(Sample {
            device_ns: 9_500_000_000,
            host_lo_ns: 500_000_010,
            host_hi_ns: 500_000_020,
        });
        assert_eq!(fit.len(), 2);
        fit.add(Sample { device_ns: 1_000, host_lo_ns: 600_000_000, host_hi_ns: 600_000_100 });
        assert_eq!(fit.len(), 1);
    }

    #[test]
    fn the_cell_hands_over_what_was_stored() {
        let cell = MappingCell::new();
        assert_eq!(cell.load(), None);
        let mut fit = ClockFit::new();
        let m = fit.add(Sample { device_ns: 7_000, host_lo_ns: 100, host_hi_ns: 300 }).unwrap();
        cell.store(&m);
        assert_eq!(cell.load(), Some(m));
    }
}
