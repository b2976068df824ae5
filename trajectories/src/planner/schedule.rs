//! Playback timing of the orbit: which argument of latitude each waypoint shows, and when.
//!
//! The plan plays `passes` sweeps of an arc of argument of latitude (the full orbit by default),
//! alternating direction after each pass (the paper's windup rule). Each pass is rest to rest:
//! the playback speed ramps up from zero with a smoothstep profile over `ramp_s`, cruises at the
//! orbit's mean motion times the time scale, and ramps down to zero at the pass's end, so the arm
//! starts, turns round and ends at rest with continuous acceleration. A ramp covers half the arc
//! it would cover at cruise speed, so a pass lasts its cruise time plus `ramp_s`.
//!
//! Waypoints are spaced evenly in time.

/// The timing of one plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    /// Arc start, radians of argument of latitude.
    pub u_start: f64,
    /// Arc length, radians (positive).
    pub span: f64,
    /// Number of passes (revolutions when the arc is the whole orbit).
    pub passes: usize,
    /// Time one pass would take at cruise speed, seconds.
    pub cruise_s: f64,
    /// Ramp-up (and ramp-down) time per pass, seconds.
    pub ramp_s: f64,
}

/// Distance covered (in cruise seconds) after `t` seconds of a pass of cruise length `cruise`
/// with ramps of `ramp` seconds. Monotonic from 0 at t = 0 to `cruise` at t = cruise + ramp.
fn covered(t: f64, cruise: f64, ramp: f64) -> f64 {
    let total = cruise + ramp;
    let t = t.clamp(0.0, total);
    if ramp <= 0.0 {
        return t;
    }
    // Integral of the smoothstep 3x^2 - 2x^3 over [0, x] is x^3 - x^4 / 2 (times the ramp time).
    let ramp_dist = |x: f64| ramp * (x * x * x - 0.5 * x * x * x * x);
    if t <= ramp {
        ramp_dist(t / ramp)
    } else if t >= total - ramp {
        cruise - ramp_dist((total - t) / ramp)
    } else {
        0.5 * ramp + (t - ramp)
    }
}

impl Schedule {
    /// Duration of one pass, seconds.
    pub fn pass_s(&self) -> f64 {
        self.cruise_s + self.ramp_s
    }

    /// Total duration, seconds.
    pub fn duration_s(&self) -> f64 {
        self.pass_s() * self.passes as f64
    }

    /// The argument of latitude shown at time `t` (windup rule applied), and the pass index.
    pub fn u_at(&self, t: f64) -> (f64, usize) {
        let pass_s = self.pass_s();
        let last = self.passes.saturating_sub(1);
        let k = ((t / pass_s).floor().max(0.0) as usize).min(last);
        let local = t - k as f64 * pass_s;
        let frac = covered(local, self.cruise_s, self.ramp_s) / self.cruise_s;
        let frac = if k.is_multiple_of(2) { frac } else { 1.0 - frac };
        (self.u_start + self.span * frac, k)
    }

    /// Evenly spaced waypoint times from 0 to the duration (`n` >= 2 of them).
    pub fn times(&self, n: usize) -> Vec<f64> {
        let d = self.duration_s();
        let last = (n - 1) as f64;
        (0..n).map(|k| if k + 1 == n { d } else { d * k as f64 / last }).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_are_continuous_and_cover_the_arc() {
        let s = Schedule { u_start: 1.0, span: 2.0, passes: 2, cruise_s: 10.0, ramp_s: 2.0 };
        assert_eq!(s.duration_s(), 24.0);
        assert_eq!(s.u_at(0.0), (1.0, 0));
        assert!((s.u_at(12.0 - 1e-9).0 - 3.0).abs() < 1e-9);
        assert!((s.u_at(12.0 + 1e-9).0 - 3.0).abs() < 1e-9);
        assert!((s.u_at(24.0).0 - 1.0).abs() < 1e-12);
        // Cruise speed in the middle of a pass: span / cruise per second.
        let v = (s.u_at(6.001).0 - s.u_at(5.999).0) / 0.002;
        assert!((v - 0.2).abs() < 1e-6, "{v}");
        // At rest at the ends.
        let v0 = (s.u_at(1e-4).0 - s.u_at(0.0).0) / 1e-4;
        assert!(v0.abs() < 1e-6, "{v0}");
        // Going back on the second pass.
        assert!(s.u_at(18.0).0 < s.u_at(17.0).0);
    }
}
