//! The lens distortion of a camera: OpenCV's Brown-Conrady model (its five coefficients, and the
//! rational form's three more), applied to and removed from normalised image coordinates.
//!
//! A point at `(x, y, 1)` in OpenCV camera axes (`x = X / Z`, `y = Y / Z`) is seen at the
//! normalised position
//!
//! ```text
//! r2 = x^2 + y^2
//! radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
//! xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
//! yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
//! ```
//!
//! and then at pixel `(fx xd + cx, fy yd + cy)` ([`crate::Intrinsics::project`]). All
//! coefficients zero is the pinhole: [`Distortion::is_none`] lets every caller take the exact
//! pinhole arithmetic it had before lenses were modelled, so a distortion-free camera's figures
//! are unchanged to the bit.

/// Which form of the Brown-Conrady model the coefficients are for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DistortionModel {
    /// Five coefficients `k1, k2, p1, p2, k3` (OpenCV's default; ROS's `plumb_bob`).
    #[default]
    BrownConrady,
    /// Eight coefficients `k1, k2, p1, p2, k3, k4, k5, k6`: the radial term is a ratio of
    /// polynomials (OpenCV's `CALIB_RATIONAL_MODEL`; ROS's `rational_polynomial`; Orbbec's
    /// `OB_DISTORTION_BROWN_CONRADY_K6`).
    RationalPolynomial,
}

impl DistortionModel {
    /// The model's name as `sensor_msgs/CameraInfo` and `foxglove.CameraCalibration` spell it.
    pub fn name(self) -> &'static str {
        match self {
            Self::BrownConrady => "plumb_bob",
            Self::RationalPolynomial => "rational_polynomial",
        }
    }

    /// The model named `name` (`plumb_bob`, `rational_polynomial`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "plumb_bob" => Some(Self::BrownConrady),
            "rational_polynomial" => Some(Self::RationalPolynomial),
            _ => None,
        }
    }

    /// How many coefficients the model has (5 or 8).
    pub fn coefficient_count(self) -> usize {
        match self {
            Self::BrownConrady => 5,
            Self::RationalPolynomial => 8,
        }
    }
}

/// A lens's distortion: the model and its coefficients in OpenCV's order
/// `k1, k2, p1, p2, k3, k4, k5, k6` (the last three zero in the five-coefficient model).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Distortion {
    pub model: DistortionModel,
    pub coefficients: [f64; 8],
}

/// Newton steps [`Distortion::undistort`] takes at most.
const UNDISTORT_ITERATIONS: usize = 20;

impl Distortion {
    /// No distortion: the pinhole.
    pub const NONE: Distortion =
        Distortion { model: DistortionModel::BrownConrady, coefficients: [0.0; 8] };

    /// OpenCV's five coefficients `[k1, k2, p1, p2, k3]`.
    pub fn brown_conrady(d: [f64; 5]) -> Self {
        let mut coefficients = [0.0; 8];
        coefficients[..5].copy_from_slice(&d);
        Distortion { model: DistortionModel::BrownConrady, coefficients }
    }

    /// The model's coefficients (5 or 8), as `/camera/calibration`'s `D` carries them.
    pub fn d(&self) -> &[f64] {
        &self.coefficients[..self.model.coefficient_count()]
    }

    /// The distortion of `model` with coefficients `d` (OpenCV's order, as many as the model
    /// has); `None` when the count is wrong or a coefficient is not finite.
    pub fn from_d(model: DistortionModel, d: &[f64]) -> Option<Self> {
        if d.len() != model.coefficient_count() || !d.iter().all(|v| v.is_finite()) {
            return None;
        }
        let mut coefficients = [0.0; 8];
        coefficients[..d.len()].copy_from_slice(d);
        Some(Distortion { model, coefficients })
    }

    /// Whether this is the pinhole (every coefficient zero).
    pub fn is_none(&self) -> bool {
        self.coefficients.iter().all(|c| *c == 0.0)
    }

    /// Whether every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.coefficients.iter().all(|c| c.is_finite())
    }

    /// Where the lens puts the ideal normalised point `(x, y)`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        if self.is_none() {
            return (x, y);
        }
        let [k1, k2, p1, p2, k3, k4, k5, k6] = self.coefficients;
        let r2 = x * x + y * y;
        let radial =
            (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// The ideal normalised point the lens put at `(xd, yd)`: the inverse of [`Self::distort`]
    /// by Gauss-Newton on the model's Jacobian (numerical), to 1e-12 in normalised units or
    /// [`UNDISTORT_ITERATIONS`] steps. Within the lens's monotonic region (every real lens's
    /// field of view) the answer is exact to well below a thousandth of a pixel.
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if self.is_none() {
            return (xd, yd);
        }
        let (mut x, mut y) = (xd, yd);
        let h = 1e-7;
        for _ in 0..UNDISTORT_ITERATIONS {
            let (u, v) = self.distort(x, y);
            let (ex, ey) = (u - xd, v - yd);
            if ex.abs() < 1e-12 && ey.abs() < 1e-12 {
                break;
            }
            let (ux, vx) = self.distort(x + h, y);
            let (uy, vy) = self.distort(x, y + h);
            let (a, b, c, d) = ((ux - u) / h, (uy - u) / h, (vx - v) / h, (vy - v) / h);
            let det = a * d - b * c;
            if det.abs() < 1e-12 || !det.is_finite() {
                break;
            }
            x -= (d * ex - b * ey) / det;
            y -= (a * ey - c * ex) / det;
        }
        (x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_distortion_is_the_identity_to_the_bit() {
        let d = Distortion::NONE;
        assert!(d.is_none());
        assert_eq!(d.distort(0.1234567, -0.7654321), (0.1234567, -0.7654321));
        assert_eq!(d.undistort(0.1234567, -0.7654321), (0.1234567, -0.7654321));
        assert_eq!(d.d(), &[0.0; 5]);
    }

    #[test]
    fn distortion_moves_points_as_opencv_s_formula_and_undistort_inverts_it() {
        let d = Distortion::brown_conrady([-0.12, 0.05, 0.001, -0.002, -0.01]);
        // By hand at (0.3, -0.2): r2 = 0.13, radial = 1 - 0.0156 + 0.000845 - 0.00002197.
        let (x, y) = (0.3, -0.2);
        let r2: f64 = 0.13;
        let radial = 1.0 - 0.12 * r2 + 0.05 * r2 * r2 - 0.01 * r2 * r2 * r2;
        let ex = x * radial + 2.0 * 0.001 * x * y + -0.002 * (r2 + 2.0 * x * x);
        let ey = y * radial + 0.001 * (r2 + 2.0 * y * y) + 2.0 * -0.002 * x * y;
        let (u, v) = d.distort(x, y);
        assert!((u - ex).abs() < 1e-15 && (v - ey).abs() < 1e-15, "({u}, {v})");
        assert!((u - x).abs() > 1e-3, "the lens moves the point");
        for (x, y) in [(0.0, 0.0), (0.3, -0.2), (-0.6, 0.4), (0.7, 0.5)] {
            let (u, v) = d.distort(x, y);
            let (bx, by) = d.undistort(u, v);
            assert!((bx - x).abs() < 1e-10 && (by - y).abs() < 1e-10, "({x}, {y}) -> ({bx}, {by})");
        }
    }

    #[test]
    fn the_rational_model_divides_the_radial_term_and_names_round_trip() {
        let mut d = Distortion::from_d(
            DistortionModel::RationalPolynomial,
            &[0.1, 0.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0],
        )
        .expect("eight coefficients");
        assert_eq!(d.d().len(), 8);
        // k1 = k4: the ratio is 1, no radial distortion.
        let (u, v) = d.distort(0.4, 0.3);
        assert!((u - 0.4).abs() < 1e-15 && (v - 0.3).abs() < 1e-15);
        d.coefficients[5] = 0.0;
        assert!(d.distort(0.4, 0.3).0 > 0.4);
        assert!(Distortion::from_d(DistortionModel::BrownConrady, &[0.0; 8]).is_none());
        assert!(Distortion::from_d(DistortionModel::BrownConrady, &[f64::NAN; 5]).is_none());
        for m in [DistortionModel::BrownConrady, DistortionModel::RationalPolynomial] {
            assert_eq!(DistortionModel::from_name(m.name()), Some(m));
        }
    }
}
