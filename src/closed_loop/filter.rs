//! The relative-navigation filter: a Kalman filter on the chaser's deviation from its plan, in
//! the plan's relative frame (RTN, real metres, orbit seconds), predicted with the
//! Hill-Clohessy-Wiltshire (HCW) model and updated with each usable pose estimate, behind a
//! Mahalanobis gate.
//!
//! The state is the deviation `x = [dr, dv]` (position, velocity) of the relative state from the
//! plan that is NOT the controller's own correction: with the target where the lab file says, it
//! is zero; with the target displaced by `d` (lab), its position part is `-R^T d / scale`. Each
//! measurement is that deviation as one capture saw it (docs/closed-loop.md). The filter is plain
//! `nalgebra` fixed-size algebra; it runs on the navigator's thread, never in the tick.

use nalgebra::{Matrix3, Matrix3x6, Matrix6, Vector3, Vector6};

/// Chi-square with 3 degrees of freedom at 99.9 %: a measurement whose squared Mahalanobis
/// distance from the prediction exceeds it is inconsistent with the filter and not used.
pub const GATE_CHI2_3DOF_999: f64 = 16.266;

/// The filter's noise model, in the plan's units (real metres, orbit seconds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterNoise {
    /// Standard deviation of one measurement's position, per axis, real metres.
    pub measurement_m: f64,
    /// White-acceleration spectral density of the deviation, m^2/s^3 (orbit time).
    pub accel_psd: f64,
    /// Initial standard deviations of position (m) and velocity (m/s).
    pub initial_position_m: f64,
    pub initial_velocity_m_s: f64,
}

impl FilterNoise {
    /// The documented defaults (docs/closed-loop.md), given in lab terms and converted with the
    /// plan's `scale` (lab metres per real metre) and `time_scale` (orbit seconds per playback
    /// second): 1 mm (lab) per axis per estimate; a deviation that may wander 0.5 mm (lab) per
    /// playback second; 10 mm and 10 mm per playback second at the start.
    pub fn lab_defaults(scale: f64, time_scale: f64) -> Self {
        let real = |lab_m: f64| lab_m / scale;
        let walk = real(0.5e-3);
        Self {
            measurement_m: real(1e-3),
            // Position variance grown by white acceleration over T: q T^3 / 3.
            accel_psd: 3.0 * walk * walk / time_scale.powi(3),
            initial_position_m: real(10e-3),
            initial_velocity_m_s: real(10e-3) / time_scale,
        }
    }
}

/// The HCW state-transition matrix over `dt` orbit seconds at mean motion `n` (rad/s), for the
/// state `[x, y, z, vx, vy, vz]` with x radial, y along-track, z orbit normal.
pub fn hcw_transition(n: f64, dt: f64) -> Matrix6<f64> {
    let (s, c) = (n * dt).sin_cos();
    let nt = n * dt;
    #[rustfmt::skip]
    let phi = Matrix6::new(
        4.0 - 3.0 * c,        0.0, 0.0, s / n,               2.0 * (1.0 - c) / n,         0.0,
        6.0 * (s - nt),       1.0, 0.0, 2.0 * (c - 1.0) / n, (4.0 * s - 3.0 * nt) / n,    0.0,
        0.0,                  0.0, c,   0.0,                 0.0,                         s / n,
        3.0 * n * s,          0.0, 0.0, c,                   2.0 * s,                     0.0,
        6.0 * n * (c - 1.0),  0.0, 0.0, -2.0 * s,            4.0 * c - 3.0,               0.0,
        0.0,                  0.0, -n * s, 0.0,              0.0,                         c,
    );
    phi
}

/// What the gate decided about one measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Gate {
    /// Used: the squared Mahalanobis distance of the innovation.
    Accepted { mahalanobis2: f64 },
    /// Not used: inconsistent with the prediction.
    Rejected { mahalanobis2: f64 },
}

/// The filter.
#[derive(Debug, Clone)]
pub struct RelNavFilter {
    n: f64,
    noise: FilterNoise,
    x: Vector6<f64>,
    p: Matrix6<f64>,
    /// Orbit time of the state, seconds; `None` before the first measurement.
    t: Option<f64>,
}

impl RelNavFilter {
    pub fn new(mean_motion_rad_s: f64, noise: FilterNoise) -> Self {
        let (sp, sv) = (noise.initial_position_m.powi(2), noise.initial_velocity_m_s.powi(2));
        let p = Matrix6::from_diagonal(&Vector6::new(sp, sp, sp, sv, sv, sv));
        Self { n: mean_motion_rad_s, noise, x: Vector6::zeros(), p, t: None }
    }

    pub fn state(&self) -> &Vector6<f64> {
        &self.x
    }

    pub fn covariance(&self) -> &Matrix6<f64> {
        &self.p
    }

    /// The position part of the deviation, real metres RTN.
    pub fn position(&self) -> Vector3<f64> {
        self.x.fixed_rows::<3>(0).into_owned()
    }

    /// Orbit time of the state (s), once a measurement has been used.
    pub fn time(&self) -> Option<f64> {
        self.t
    }

    /// Predict the state to orbit time `t` (HCW, white-acceleration process noise). A time
    /// before the state's is not predicted back: the state stays.
    pub fn predict_to(&mut self, t: f64) {
        let Some(t0) = self.t else {
            self.t = Some(t);
            return;
        };
        let dt = t - t0;
        if dt <= 0.0 {
            return;
        }
        let phi = hcw_transition(self.n, dt);
        let q = self.noise.accel_psd;
        let (q11, q12, q22) = (q * dt.powi(3) / 3.0, q * dt * dt / 2.0, q * dt);
        let mut qm = Matrix6::zeros();
        for i in 0..3 {
            qm[(i, i)] = q11;
            qm[(i, i + 3)] = q12;
            qm[(i + 3, i)] = q12;
            qm[(i + 3, i + 3)] = q22;
        }
        self.x = phi * self.x;
        self.p = phi * self.p * phi.transpose() + qm;
        self.t = Some(t);
    }

    /// Update with a measured position deviation `z` (real metres RTN) at orbit time `t`, with
    /// per-axis standard deviation `sigma_m` (the backend's, or the default), behind the gate.
    /// A rejected measurement leaves the state as predicted.
    pub fn update(&mut self, t: f64, z: &Vector3<f64>, sigma_m: f64) -> Gate {
        self.predict_to(t);
        let h = Matrix3x6::<f64>::identity();
        let r = Matrix3::from_diagonal_element(sigma_m * sigma_m);
        let y = z - h * self.x;
        let s = h * self.p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            return Gate::Rejected { mahalanobis2: f64::INFINITY };
        };
        let d2 = (y.transpose() * s_inv * y)[(0, 0)];
        if !d2.is_finite() || d2 > GATE_CHI2_3DOF_999 {
            return Gate::Rejected { mahalanobis2: d2 };
        }
        let k = self.p * h.transpose() * s_inv;
        self.x += k * y;
        // Joseph form: stays symmetric positive definite with rounding.
        let i_kh = Matrix6::identity() - k * h;
        self.p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        Gate::Accepted { mahalanobis2: d2 }
    }

    /// The default measurement standard deviation.
    pub fn default_sigma_m(&self) -> f64 {
        self.noise.measurement_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: f64 = 1.4571e-4;

    #[test]
    fn hcw_keeps_an_along_track_station_and_matches_the_closed_form_ellipse() {
        let phi = hcw_transition(N, 5000.0);
        // A point along-track at rest is an equilibrium.
        let x = phi * Vector6::new(0.0, 10.0, 0.0, 0.0, 0.0, 0.0);
        assert!((x - Vector6::new(0.0, 10.0, 0.0, 0.0, 0.0, 0.0)).norm() < 1e-9, "{x}");
        // The 2:1 ellipse x = -r cos(nt), y = 2 r sin(nt) is a natural motion.
        let r = 5.0;
        let at = |t: f64| {
            let u = N * t;
            Vector6::new(
                -r * u.cos(),
                2.0 * r * u.sin(),
                0.0,
                r * N * u.sin(),
                2.0 * r * N * u.cos(),
                0.0,
            )
        };
        let got = phi * at(0.0);
        assert!((got - at(5000.0)).norm() < 1e-9, "{got} vs {}", at(5000.0));
    }

    fn filter() -> RelNavFilter {
        RelNavFilter::new(N, FilterNoise::lab_defaults(7.7e-3, 500.0))
    }

    #[test]
    fn converges_on_a_constant_deviation() {
        let mut f = filter();
        let z = Vector3::new(0.3, -0.65, 0.1);
        let sigma = f.default_sigma_m();
        for i in 0..20 {
            let gate = f.update(i as f64 * 250.0, &z, sigma);
            assert!(matches!(gate, Gate::Accepted { .. }), "{gate:?}");
        }
        assert!((f.position() - z).norm() < 0.02, "{}", f.position());
        assert!(f.covariance()[(0, 0)].sqrt() < sigma, "the covariance shrinks");
    }

    #[test]
    fn the_gate_rejects_an_outlier_and_keeps_the_state() {
        let mut f = filter();
        let z = Vector3::new(0.0, 0.65, 0.0);
        let sigma = f.default_sigma_m();
        for i in 0..10 {
            f.update(i as f64 * 250.0, &z, sigma);
        }
        let before = f.position();
        // 20 mm (lab) off where the filter expects it: 2.6 m real.
        let outlier = z + Vector3::new(2.6, 0.0, 0.0);
        let gate = f.update(10.0 * 250.0, &outlier, sigma);
        let Gate::Rejected { mahalanobis2 } = gate else { panic!("accepted {gate:?}") };
        assert!(mahalanobis2 > GATE_CHI2_3DOF_999);
        assert!((f.position() - before).norm() < 0.01, "state kept");
        // The next consistent one is used.
        assert!(matches!(f.update(11.0 * 250.0, &z, sigma), Gate::Accepted { .. }));
    }

    #[test]
    fn holds_a_constant_deviation_at_a_fast_time_scale() {
        // The fly-around of tests/closed_loop.rs: one revolution in 20 s played at half speed,
        // a capture every second of playback (n * dt = 0.157 rad between captures).
        let (scale, time_scale) = (7.7e-3, 1078.0);
        let mut f = RelNavFilter::new(N, FilterNoise::lab_defaults(scale, time_scale));
        let z = Vector3::new(0.0, 0.0, 0.005 / scale);
        let sigma = f.default_sigma_m();
        let mut worst_late = 0.0f64;
        for i in 0..40 {
            f.update(i as f64 * time_scale, &z, sigma);
            if i >= 10 {
                worst_late = worst_late.max((f.position() - z).norm() * scale);
            }
        }
        eprintln!("worst after 10 captures: {:.4} mm (lab)", worst_late * 1e3);
        assert!(worst_late < 0.2e-3, "{:.4} mm", worst_late * 1e3);
    }
}
