//! Relative orbital motion as the paper defines it: the chief's classical orbital elements, the
//! relative orbital elements (ROE) of the chaser, the first-order ROE-to-HCW mapping (the paper's
//! eq. (3)) evaluated at discrete arguments of latitude, and the oriented Sun phase angle.
//!
//! Frames: **RTN** (= HCW) has `x` radial (out of the Earth), `y` transverse (along-track, the
//! chief's direction of motion) and `z` normal (along the chief's orbital angular momentum).
//! **ECI** is the Earth-centred inertial frame the chief's elements are given in.
//!
//! Nothing here integrates anything: positions are the closed form of eq. (3) at each `u`.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// Earth's standard gravitational parameter, m^3/s^2 (IERS/WGS-84 value).
pub const MU_EARTH: f64 = 3.986_004_418e14;

/// The paper's time scale: playback runs 500 times faster than the orbit.
pub const PAPER_TIME_SCALE: f64 = 500.0;

/// The chief's classical orbital elements (ECI). Angles in degrees, as the paper's table lists them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChiefOrbit {
    /// Semi-major axis, metres.
    pub a_m: f64,
    /// Eccentricity. The first-order mapping assumes a near-circular chief.
    pub e: f64,
    pub i_deg: f64,
    pub raan_deg: f64,
    pub argp_deg: f64,
    /// Initial true anomaly.
    pub nu0_deg: f64,
}

impl Default for ChiefOrbit {
    /// The paper's defaults: a = 26 578 km, e = 0, i = 51.6 deg, RAAN 0, argp 0, nu0 = 270 deg.
    fn default() -> Self {
        Self {
            a_m: 26_578_000.0,
            e: 0.0,
            i_deg: 51.6,
            raan_deg: 0.0,
            argp_deg: 0.0,
            nu0_deg: 270.0,
        }
    }
}

impl ChiefOrbit {
    /// Mean motion n = sqrt(mu / a^3), rad/s.
    pub fn mean_motion(&self) -> f64 {
        (MU_EARTH / self.a_m.powi(3)).sqrt()
    }

    /// Orbital period 2 pi / n, seconds (about 43 100 s for the default orbit).
    pub fn period_s(&self) -> f64 {
        TAU / self.mean_motion()
    }

    /// Initial argument of latitude u0 = argp + nu0 (radians, in [0, 2 pi)). For the circular
    /// chief true, mean and eccentric anomalies coincide, so this is also the mean argument.
    pub fn u0_rad(&self) -> f64 {
        (self.argp_deg + self.nu0_deg).to_radians().rem_euclid(TAU)
    }

    /// The RTN axes in ECI at argument of latitude `u`, as the columns (R, T, N) of a rotation
    /// matrix: `v_eci = M * v_rtn`.
    pub fn rtn_to_eci(&self, u: f64) -> Matrix3<f64> {
        let (so, co) = self.raan_deg.to_radians().sin_cos();
        let (si, ci) = self.i_deg.to_radians().sin_cos();
        let (su, cu) = u.sin_cos();
        let r = Vector3::new(co * cu - so * su * ci, so * cu + co * su * ci, su * si);
        let n = Vector3::new(so * si, -co * si, ci);
        let t = n.cross(&r);
        Matrix3::from_columns(&[r, t, n])
    }
}

/// The dimensionless relative orbital elements of the paper's eq. (1), in its order:
/// delta a, delta lambda, delta e_x, delta e_y, delta i_x, delta i_y.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Roe(pub [f64; 6]);

impl Roe {
    pub fn da(&self) -> f64 {
        self.0[0]
    }
    pub fn dlambda(&self) -> f64 {
        self.0[1]
    }
    pub fn dex(&self) -> f64 {
        self.0[2]
    }
    pub fn dey(&self) -> f64 {
        self.0[3]
    }
    pub fn dix(&self) -> f64 {
        self.0[4]
    }
    pub fn diy(&self) -> f64 {
        self.0[5]
    }

    /// Eq. (3): the chaser's position relative to the chief in RTN (metres) at argument of
    /// latitude `u`, for a chief of semi-major axis `a` whose trajectory starts at `u0`.
    pub fn position_rtn(&self, a: f64, u: f64, u0: f64) -> Vector3<f64> {
        let (su, cu) = u.sin_cos();
        Vector3::new(
            a * (self.da() - self.dex() * cu - self.dey() * su),
            a * (self.dlambda() - 1.5 * self.da() * (u - u0) + 2.0 * self.dex() * su
                - 2.0 * self.dey() * cu),
            a * (self.dix() * su - self.diy() * cu),
        )
    }

    /// d/du of [`Roe::position_rtn`] (multiply by n for the velocity in m/s).
    pub fn position_rtn_du(&self, a: f64, u: f64) -> Vector3<f64> {
        let (su, cu) = u.sin_cos();
        Vector3::new(
            a * (self.dex() * su - self.dey() * cu),
            a * (-1.5 * self.da() + 2.0 * self.dex() * cu + 2.0 * self.dey() * su),
            a * (self.dix() * cu + self.diy() * su),
        )
    }
}

/// The planner's named relative motions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// The paper's fly-around: delta e_x = delta i_y = r/a, everything else 0. A closed, drift-free
    /// 2:1 ellipse (radial amplitude r, along-track 2r, cross-track r).
    Flyaround,
    /// A fixed point at range r along-track: delta lambda = r/a, everything else 0.
    StationKeeping,
}

impl Preset {
    pub const ALL: [Preset; 2] = [Preset::Flyaround, Preset::StationKeeping];

    pub fn name(&self) -> &'static str {
        match self {
            Preset::Flyaround => "flyaround",
            Preset::StationKeeping => "station-keeping",
        }
    }

    /// Parse a preset name as the CLI spells it.
    pub fn from_name(name: &str) -> Option<Preset> {
        Preset::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The ROE of this preset for a nominal range `range_m` around a chief of semi-major axis `a_m`.
    pub fn roe(&self, range_m: f64, a_m: f64) -> Roe {
        let k = range_m / a_m;
        match self {
            Preset::Flyaround => Roe([0.0, 0.0, k, 0.0, 0.0, k]),
            Preset::StationKeeping => Roe([0.0, k, 0.0, 0.0, 0.0, 0.0]),
        }
    }
}

/// The windup rule: revolution `k` (0-based) runs forward when `k` is even and backward when odd,
/// so the arm never turns more than one revolution in one direction. `s` in `[0, revolutions]` is
/// the playback progress in revolutions; the result is the argument of latitude at which eq. (3)
/// is evaluated: `u0 + 2 pi * (s - k)` on forward revolutions, `u0 + 2 pi * (k + 1 - s)` on
/// backward ones. It is continuous in `s`.
pub fn windup_u(u0: f64, s: f64) -> f64 {
    let k = s.floor().max(0.0);
    let frac = s - k;
    let k_int = k as u64;
    // At an exact integer s the revolution that just ended decides (continuity either way).
    if k_int.is_multiple_of(2) {
        u0 + TAU * frac
    } else {
        u0 + TAU * (1.0 - frac)
    }
}

/// The direction of revolution `k` under the windup rule: +1 forward, -1 backward.
pub fn windup_direction(k: usize) -> i8 {
    if k.is_multiple_of(2) {
        1
    } else {
        -1
    }
}

/// The Sun direction used when none is given: ECI +X, the Sun at the March equinox.
pub const DEFAULT_SUN_ECI: [f64; 3] = [1.0, 0.0, 0.0];

/// The oriented Sun phase angle, degrees in [0, 360), of a chaser at `rel_rtn` (RTN, metres)
/// from the chief at argument of latitude `u`, with the Sun in direction `sun_eci` (ECI, any
/// length; the Sun is far enough for the direction to be the same at chief and chaser).
///
/// The unsigned phase angle is the angle between target-to-Sun and target-to-chaser: 0 with the
/// chaser between Sun and target, 180 with the target between Sun and chaser. Its orientation
/// comes from the chief's orbit normal N: in RTN the Sun turns about -N once per orbit, so a
/// chaser ahead of the Sun about +N ((sun x chaser) . N >= 0) is approaching occultation and
/// keeps the unsigned angle (0-180); one behind is leaving it and gets 360 minus the angle
/// (180-360). A chaser at rest in RTN thus sweeps 0 -> 180 -> 360 once per orbit.
/// Returns `None` for a chaser at the target (no direction).
pub fn sun_phase_deg(
    chief: &ChiefOrbit,
    u: f64,
    rel_rtn: &Vector3<f64>,
    sun_eci: &Vector3<f64>,
) -> Option<f64> {
    let rho = rel_rtn.try_normalize(1e-12)?;
    let sun_rtn = (chief.rtn_to_eci(u).transpose() * sun_eci).try_normalize(1e-12)?;
    let cos = sun_rtn.dot(&rho).clamp(-1.0, 1.0);
    let sin = sun_rtn.cross(&rho).norm();
    let unsigned = sin.atan2(cos).to_degrees();
    let side = sun_rtn.cross(&rho).z;
    let oriented = if side >= 0.0 { unsigned } else { 360.0 - unsigned };
    Some(if oriented >= 360.0 { oriented - 360.0 } else { oriented })
}

/// Wrap an angle to [0, 2 pi).
pub fn wrap_tau(x: f64) -> f64 {
    let w = x.rem_euclid(TAU);
    if w >= TAU {
        0.0
    } else {
        w
    }
}

/// Degrees of an angle wrapped to [0, 360).
pub fn wrapped_deg(x: f64) -> f64 {
    wrap_tau(x) * 180.0 / PI
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_orbit_period_is_about_twelve_hours() {
        let c = ChiefOrbit::default();
        let t = c.period_s();
        assert!((t - 43_122.0).abs() < 10.0, "{t}");
        assert!((c.u0_rad() - 1.5 * PI).abs() < 1e-12);
    }

    #[test]
    fn rtn_axes_are_orthonormal_and_right_handed() {
        let c = ChiefOrbit { raan_deg: 30.0, ..ChiefOrbit::default() };
        let m = c.rtn_to_eci(0.7);
        assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-12);
        assert!((m.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn windup_alternates_and_is_continuous() {
        let u0 = 1.0;
        assert!((windup_u(u0, 0.25) - (u0 + TAU * 0.25)).abs() < 1e-12);
        assert!((windup_u(u0, 1.25) - (u0 + TAU * 0.75)).abs() < 1e-12);
        assert!((windup_u(u0, 2.25) - (u0 + TAU * 0.25)).abs() < 1e-12);
        for s in [1.0, 2.0, 3.0] {
            let a = windup_u(u0, s - 1e-9);
            let b = windup_u(u0, s + 1e-9);
            assert!((a - b).abs() < 1e-6, "jump at {s}: {a} {b}");
        }
        assert_eq!(windup_direction(0), 1);
        assert_eq!(windup_direction(1), -1);
    }
}
