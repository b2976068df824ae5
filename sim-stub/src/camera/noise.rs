//! The simulated camera's noise options (the paper's sigma_px and sigma_theta, and a
//! range-dependent depth noise), drawn from a generator seeded per capture so that a run's frames
//! are the same every time.

use nalgebra::{UnitQuaternion, Vector3};
use rand::rngs::Xoshiro256PlusPlus;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Noise applied to a rendered frame. All zero (the default) renders a clean frame, as the
/// paper's default noise level does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Standard deviation of a per-frame 2-D image translation, pixels: the frame is rendered
    /// with its principal point moved by (dx, dy) ~ N(0, sigma_px^2) each, while the delivered
    /// intrinsics stay nominal, so every projected keypoint of the frame is off by the same
    /// (dx, dy). This is the paper's "2D keypoint translation noise" applied to the image.
    pub sigma_px: f64,
    /// Standard deviation of the camera orientation error, degrees: the frame is rendered from
    /// the nominal camera pose turned by a rotation vector whose three components (camera axes)
    /// are each N(0, sigma_theta^2). Ground truth keeps the nominal pose.
    pub sigma_theta_deg: f64,
    /// Range-dependent depth noise: each valid depth z gets N(0, (k z^2)^2) added, the usual
    /// model of stereo/structured-light sensors whose error grows with the square of the range.
    /// `k` in 1/m; 0.0 turns it off. About 0.002 is typical of a Gemini-class sensor (2 mm at
    /// 1 m).
    pub depth_k_per_m: f64,
    /// Seed; the generator of a capture is seeded with (seed, capture tick).
    pub seed: u64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self { sigma_px: 0.0, sigma_theta_deg: 0.0, depth_k_per_m: 0.0, seed: 0 }
    }
}

impl NoiseModel {
    /// Why the options were refused, or `None`.
    pub fn check(&self) -> Option<String> {
        let v = [self.sigma_px, self.sigma_theta_deg, self.depth_k_per_m];
        if v.iter().all(|x| x.is_finite() && *x >= 0.0) {
            None
        } else {
            Some(format!(
                "noise sigma_px {}, sigma_theta_deg {}, depth_k_per_m {} must be finite and >= 0",
                self.sigma_px, self.sigma_theta_deg, self.depth_k_per_m
            ))
        }
    }

    /// The draws of one capture.
    pub fn draw(&self, tick: u64) -> FrameNoise {
        let mut rng = self.rng(tick);
        let mut gauss = |sigma: f64| -> f64 {
            match Normal::new(0.0, sigma) {
                Ok(n) if sigma > 0.0 => n.sample(&mut rng),
                _ => 0.0,
            }
        };
        let shift_px = [gauss(self.sigma_px), gauss(self.sigma_px)];
        let s = self.sigma_theta_deg.to_radians();
        let rotvec = Vector3::new(gauss(s), gauss(s), gauss(s));
        FrameNoise {
            shift_px,
            rotation: UnitQuaternion::from_scaled_axis(rotvec),
            depth_k_per_m: self.depth_k_per_m,
            depth_rng: self.rng(tick ^ 0xD5A7_4C1E_9B3F_0E21),
        }
    }

    fn rng(&self, tick: u64) -> Xoshiro256PlusPlus {
        let key = self.seed ^ tick.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(17);
        Xoshiro256PlusPlus::seed_from_u64(key)
    }
}

/// What the noise of one capture came out as.
#[derive(Debug, Clone)]
pub struct FrameNoise {
    /// Principal point shift used for the render, pixels (x, y).
    pub shift_px: [f64; 2],
    /// Rotation applied to the camera's orientation, in camera axes.
    pub rotation: UnitQuaternion<f64>,
    depth_k_per_m: f64,
    depth_rng: Xoshiro256PlusPlus,
}

impl FrameNoise {
    /// No noise at all.
    pub fn none() -> Self {
        NoiseModel::default().draw(0)
    }

    /// Add the range-dependent depth noise to every valid depth (0 stays 0; never negative).
    pub fn apply_depth(&mut self, depth: &mut [f32]) {
        if self.depth_k_per_m <= 0.0 {
            return;
        }
        let unit = match Normal::new(0.0, 1.0) {
            Ok(n) => n,
            Err(_) => return,
        };
        for z in depth.iter_mut().filter(|z| **z > 0.0) {
            let zf = f64::from(*z);
            let noisy = zf + self.depth_k_per_m * zf * zf * unit.sample(&mut self.depth_rng);
            *z = noisy.max(1e-6) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_are_seeded_per_capture() {
        let n = NoiseModel { sigma_px: 1.0, sigma_theta_deg: 0.5, depth_k_per_m: 0.01, seed: 7 };
        let a = n.draw(3);
        let b = n.draw(3);
        let c = n.draw(4);
        assert_eq!(a.shift_px, b.shift_px);
        assert_ne!(a.shift_px, c.shift_px);
        assert!(a.rotation.angle() > 0.0 && a.rotation.angle() < 0.1);
        assert_eq!(FrameNoise::none().shift_px, [0.0, 0.0]);
    }

    #[test]
    fn depth_noise_grows_with_the_square_of_range() {
        let n = NoiseModel { depth_k_per_m: 0.01, ..NoiseModel::default() };
        let spread = |z: f32| {
            let mut d = vec![z; 20_000];
            n.draw(1).apply_depth(&mut d);
            let m = d.iter().map(|v| f64::from(*v)).sum::<f64>() / d.len() as f64;
            (d.iter().map(|v| (f64::from(*v) - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
        };
        let (s1, s2) = (spread(1.0), spread(2.0));
        assert!((s1 - 0.01).abs() < 0.0005, "{s1}");
        assert!((s2 - 0.04).abs() < 0.002, "{s2}");
        let mut zero = vec![0.0f32; 10];
        n.draw(1).apply_depth(&mut zero);
        assert!(zero.iter().all(|z| *z == 0.0));
    }
}
