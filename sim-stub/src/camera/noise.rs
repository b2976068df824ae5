//! The simulated camera's noise options (the paper's sigma_px and sigma_theta, a range-dependent
//! depth noise, and a depth model of the Orbbec stereo camera), drawn from a generator seeded per
//! capture so that a run's frames are the same every time.
//!
//! The Orbbec model ([`DepthModel::Orbbec`], figures and their sources in docs/sim-camera.md):
//! depth error with a standard deviation growing with z^2; no depth nearer than the minimum
//! range; and invalid pixels (depth 0, as [`hitl_hal::RgbdFrame`] marks "no return") at depth
//! edges, where the projector or the second IR camera (each a known distance to the side along
//! the camera's x axis) cannot see the surface, and where the surface is seen at a grazing angle.
//! Every decision is taken on the rendered (clean) depth, so one invalid pixel does not spread.

use hitl_hal::Intrinsics;
use nalgebra::{UnitQuaternion, Vector3};
use rand::rngs::Xoshiro256PlusPlus;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, StandardNormal};

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
    /// How the depth image is degraded beyond `depth_k_per_m`: not at all ([`DepthModel::Ideal`],
    /// the default), or as an Orbbec stereo camera would.
    pub depth_model: DepthModel,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self {
            sigma_px: 0.0,
            sigma_theta_deg: 0.0,
            depth_k_per_m: 0.0,
            seed: 0,
            depth_model: DepthModel::Ideal,
        }
    }
}

/// The depth camera's error model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum DepthModel {
    /// Depth as rendered: every surface pixel valid and exact (what the SITL accuracy figures in
    /// the README were measured with).
    #[default]
    Ideal,
    /// An active stereo camera's depth ([`StereoDepth::GEMINI_305`] for the lab's camera).
    Orbbec(StereoDepth),
}

/// The parameters of an active-stereo depth camera (docs/sim-camera.md gives the source of each
/// default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoDepth {
    /// Depth error standard deviation over z^2, 1/m: sigma_z = k z^2.
    pub k_per_m: f64,
    /// Nearest valid depth, metres; nearer is invalid.
    pub min_range_m: f64,
    /// Position of the second IR camera along the depth camera's x axis, metres (the stereo
    /// baseline): a surface it cannot see has no match and no depth.
    pub baseline_m: f64,
    /// Position of the pattern projector along the depth camera's x axis, metres: a surface in
    /// its shadow gets no pattern and no depth.
    pub projector_x_m: f64,
    /// A jump between neighbouring pixels beyond this fraction of the nearer depth is a depth
    /// edge; pixels on both sides of it are invalid.
    pub edge_jump: f64,
    /// Pixels whose surface is seen more than this far from head-on, degrees, are invalid.
    pub grazing_deg: f64,
}

impl StereoDepth {
    /// The Orbbec Gemini 305 (the lab's camera, docs/orbbec.md): 1 % spatial precision at 0.5 m
    /// (k = 0.02 /m), 18 mm baseline, 4 cm minimum range (Orbbec's Gemini 305 specifications);
    /// the projector half-way between the IR cameras, edge and grazing limits: the model's own
    /// assumptions (docs/sim-camera.md).
    pub const GEMINI_305: StereoDepth = StereoDepth {
        k_per_m: 0.02,
        min_range_m: 0.04,
        baseline_m: 0.018,
        projector_x_m: 0.009,
        edge_jump: 0.02,
        grazing_deg: 80.0,
    };

    /// The depth error's standard deviation at range `z_m`, metres.
    pub fn sigma_m(&self, z_m: f64) -> f64 {
        self.k_per_m * z_m * z_m
    }

    fn check(&self) -> Option<String> {
        let s = self;
        let ok = [s.k_per_m, s.min_range_m, s.edge_jump].iter().all(|x| x.is_finite() && *x >= 0.0)
            && s.baseline_m.is_finite()
            && s.projector_x_m.is_finite()
            && s.grazing_deg > 0.0
            && s.grazing_deg <= 90.0;
        (!ok).then(|| format!("depth model {s:?}: values out of range"))
    }
}

impl NoiseModel {
    /// Why the options were refused, or `None`.
    pub fn check(&self) -> Option<String> {
        let v = [self.sigma_px, self.sigma_theta_deg, self.depth_k_per_m];
        if v.iter().all(|x| x.is_finite() && *x >= 0.0) {
            match &self.depth_model {
                DepthModel::Ideal => None,
                DepthModel::Orbbec(m) => m.check(),
            }
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
            depth_model: self.depth_model,
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
    depth_model: DepthModel,
    depth_rng: Xoshiro256PlusPlus,
}

impl FrameNoise {
    /// No noise at all.
    pub fn none() -> Self {
        NoiseModel::default().draw(0)
    }

    /// Degrade the rendered depth image (row-major, `intr.width` x `intr.height`, 0 = no
    /// return): the depth model first (invalid pixels, then its error), then the extra
    /// `depth_k_per_m` noise on every valid depth. 0 stays 0; never negative.
    pub fn apply_depth(&mut self, depth: &mut [f32], intr: &Intrinsics) {
        if let DepthModel::Orbbec(m) = self.depth_model {
            stereo_depth(&m, depth, intr, &mut self.depth_rng);
        }
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

/// The Orbbec model on `depth`: pixels invalid at edges, in the projector's or the second
/// camera's shadow, at grazing angles and nearer than the minimum range; the rest get
/// N(0, (k z^2)^2) added, drawn in pixel order from `rng` (rand_distr's Ziggurat
/// `StandardNormal`, only for the pixels that keep a depth).
///
/// Written for 1280x800 at 10 Hz on the simulated camera's readout thread (issue 23): one pass
/// per test over rows, the rays' x/z and y/z per column and row computed once, the grazing test
/// without a square root or a division, each row's shadows from both viewpoints while it is in
/// cache, no library call per pixel ([`round`]), and in place: every test reads the rendered
/// depth before the last pass writes over it, one pixel at a time (docs/sim-camera.md, "Where it
/// runs", gives its time).
fn stereo_depth(
    m: &StereoDepth,
    depth: &mut [f32],
    intr: &Intrinsics,
    rng: &mut Xoshiro256PlusPlus,
) {
    let (w, h) = (intr.width as usize, intr.height as usize);
    if w == 0 || h == 0 || depth.len() != w * h {
        return;
    }
    let mut invalid = vec![false; w * h];
    mark_edges(depth, w, h, m.edge_jump, &mut invalid);
    // Shadows: what a viewpoint `dx` metres along x cannot see.
    let mut scratch = ShadowRow::new(w);
    for v in 0..h {
        let row = v * w..(v + 1) * w;
        for dx in [m.projector_x_m, m.baseline_m] {
            if dx != 0.0 {
                scratch.mark(
                    &depth[row.clone()],
                    intr.fx * dx,
                    m.edge_jump,
                    &mut invalid[row.clone()],
                );
            }
        }
    }
    mark_grazing(depth, intr, m.grazing_deg, &mut invalid);
    for (d, bad) in depth.iter_mut().zip(&invalid) {
        let zf = f64::from(*d);
        if *bad || zf.is_nan() || zf < m.min_range_m {
            *d = 0.0;
            continue;
        }
        let unit: f64 = StandardNormal.sample(rng);
        let noisy = zf + m.sigma_m(zf) * unit;
        *d = noisy.max(m.min_range_m) as f32;
    }
}

/// `x.round()` (half away from zero) without the C library call the x86-64 baseline (SSE2, no
/// SSE4.1 `roundsd`) compiles it to: three a pixel, an eighth of the model's time (`perf`). The same
/// value for every |x| < 2^53 except just below 0.5 (0.49999999999999994 gives 1), irrelevant
/// to a pixel column; NaN gives 0.
#[inline]
fn round(x: f64) -> f64 {
    ((x.abs() + 0.5) as i64 as f64).copysign(x)
}

/// Depth edges: a jump to the right or lower neighbour beyond `jump` of the nearer depth (or to
/// no return) invalidates both sides.
fn mark_edges(clean: &[f32], w: usize, h: usize, jump: f64, invalid: &mut [bool]) {
    let edge = |a: f64, b: f64| -> bool {
        if a > 0.0 {
            b <= 0.0 || (a - b).abs() > jump * a.min(b)
        } else {
            b > 0.0
        }
    };
    for v in 0..h {
        let row = &clean[v * w..(v + 1) * w];
        let below = (v + 1 < h).then(|| &clean[(v + 1) * w..(v + 2) * w]);
        for u in 0..w {
            let a = f64::from(row[u]);
            if u + 1 < w && edge(a, f64::from(row[u + 1])) {
                invalid[v * w + u] = true;
                invalid[v * w + u + 1] = true;
            }
            if let Some(below) = below {
                if edge(a, f64::from(below[u])) {
                    invalid[v * w + u] = true;
                    invalid[(v + 1) * w + u] = true;
                }
            }
        }
    }
}

/// Grazing angles: a pixel whose surface (its normal from the neighbours' back-projections) is
/// seen more than `grazing_deg` from head-on is invalid. With the ray of pixel (u, v) at depth d
/// being d (x_u, y_v, 1), the test cos < cos_max is (n.p)^2 < cos_max^2 |n|^2 |p|^2.
fn mark_grazing(clean: &[f32], intr: &Intrinsics, grazing_deg: f64, invalid: &mut [bool]) {
    let (w, h) = (intr.width as usize, intr.height as usize);
    let cos2 = grazing_deg.to_radians().cos().powi(2);
    let xs: Vec<f64> = (0..w).map(|u| (u as f64 - intr.cx) / intr.fx).collect();
    let ys: Vec<f64> = (0..h).map(|v| (v as f64 - intr.cy) / intr.fy).collect();
    for v in 1..h.saturating_sub(1) {
        let (up, row, down) = (&clean[(v - 1) * w..], &clean[v * w..], &clean[(v + 1) * w..]);
        let y = ys[v];
        for u in 1..w - 1 {
            let i = v * w + u;
            let d = f64::from(row[u]);
            if invalid[i] || d <= 0.0 {
                continue;
            }
            let (dl, dr) = (f64::from(row[u - 1]), f64::from(row[u + 1]));
            let (du, dd) = (f64::from(up[u]), f64::from(down[u]));
            // Across: p(u+1) - p(u-1); along: p(v+1) - p(v-1).
            let a = Vector3::new(xs[u + 1] * dr - xs[u - 1] * dl, y * (dr - dl), dr - dl);
            let b = Vector3::new(xs[u] * (dd - du), ys[v + 1] * dd - ys[v - 1] * du, dd - du);
            let n = a.cross(&b);
            let p = Vector3::new(xs[u], y, 1.0);
            let np = n.dot(&p);
            let lhs = np * np;
            let rhs = cos2 * n.norm_squared() * p.norm_squared();
            // A degenerate normal (n = 0) is left valid, as a NaN cosine was.
            if rhs > 0.0 && lhs < rhs {
                invalid[i] = true;
            }
        }
    }
}

/// Scratch for [`ShadowRow::mark`], one row long, kept between rows.
struct ShadowRow {
    buf: Vec<f64>,
    shifted: Vec<f64>,
}

impl ShadowRow {
    fn new(w: usize) -> Self {
        Self { buf: vec![f64::INFINITY; w], shifted: vec![0.0; w] }
    }

    /// Marks the pixels of one `row` of depth that a viewpoint moved along the camera's x axis
    /// cannot see: `fb` is focal length times the offset (pixels times metres), so a point at
    /// depth z appears `fb / z` pixels to the left from there. The row is splatted into a depth
    /// buffer of the moved view (neighbours on one surface fill the columns between them), and
    /// a pixel farther than that buffer where it lands is hidden.
    fn mark(&mut self, row: &[f32], fb: f64, jump: f64, invalid: &mut [bool]) {
        let w = row.len();
        let (buf, shifted) = (&mut self.buf, &mut self.shifted);
        buf.fill(f64::INFINITY);
        for (u, (s, z)) in shifted.iter_mut().zip(row).enumerate() {
            *s = u as f64 - fb / f64::from(*z);
        }
        for u in 0..w {
            let a = f64::from(row[u]);
            if a <= 0.0 {
                continue;
            }
            let s = shifted[u];
            let (mut lo, mut hi, mut near) = (s, s, a);
            if u + 1 < w {
                let b = f64::from(row[u + 1]);
                if b > 0.0 && (a - b).abs() <= jump * a.min(b) {
                    let t = shifted[u + 1];
                    (lo, hi, near) = (s.min(t), s.max(t), a.min(b));
                }
            }
            let first = round(lo).max(0.0);
            let last = round(hi).min(w as f64 - 1.0);
            if first > last {
                continue;
            }
            for b in &mut buf[first as usize..=last as usize] {
                *b = b.min(near);
            }
        }
        for u in 0..w {
            let a = f64::from(row[u]);
            if a <= 0.0 {
                continue;
            }
            let c = round(shifted[u]);
            if c >= 0.0 && c < w as f64 && a > buf[c as usize] * (1.0 + jump) {
                invalid[u] = true;
            }
        }
    }
}

#[cfg(test)]
#[path = "noise_reference.rs"]
mod reference;

#[cfg(test)]
mod tests {
    use super::*;

    fn intr(w: u32, h: u32, f: f64) -> Intrinsics {
        Intrinsics {
            width: w,
            height: h,
            fx: f,
            fy: f,
            cx: (w as f64 - 1.0) / 2.0,
            cy: (h as f64 - 1.0) / 2.0,
            distortion: Default::default(),
        }
    }

    fn orbbec(seed: u64) -> NoiseModel {
        NoiseModel {
            seed,
            depth_model: DepthModel::Orbbec(StereoDepth::GEMINI_305),
            ..NoiseModel::default()
        }
    }

    /// Mean and standard deviation of the valid pixels, and the valid fraction.
    fn stats(d: &[f32]) -> (f64, f64, f64) {
        let v: Vec<f64> = d.iter().filter(|z| **z > 0.0).map(|z| f64::from(*z)).collect();
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let s = (v.iter().map(|z| (z - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
        (m, s, v.len() as f64 / d.len() as f64)
    }

    #[test]
    fn draws_are_seeded_per_capture() {
        let n = NoiseModel {
            sigma_px: 1.0,
            sigma_theta_deg: 0.5,
            depth_k_per_m: 0.01,
            seed: 7,
            ..NoiseModel::default()
        };
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
        let k = intr(200, 100, 100.0);
        let spread = |z: f32| {
            let mut d = vec![z; 20_000];
            n.draw(1).apply_depth(&mut d, &k);
            stats(&d).1
        };
        let (s1, s2) = (spread(1.0), spread(2.0));
        assert!((s1 - 0.01).abs() < 0.0005, "{s1}");
        assert!((s2 - 0.04).abs() < 0.002, "{s2}");
        let mut zero = vec![0.0f32; 10];
        n.draw(1).apply_depth(&mut zero, &intr(10, 1, 10.0));
        assert!(zero.iter().all(|z| *z == 0.0));
    }

    #[test]
    fn orbbec_error_follows_the_datasheet_at_one_and_three_metres() {
        // A wall square to the camera: no edge, no shadow, no grazing angle; every pixel valid,
        // spread k z^2 with k = 0.02 /m (1 % at 0.5 m): 20 mm at 1 m, 180 mm at 3 m.
        let k = intr(160, 100, 140.0);
        for (z, want) in [(1.0f32, 0.020), (3.0, 0.180)] {
            let mut d = vec![z; 160 * 100];
            orbbec(5).draw(2).apply_depth(&mut d, &k);
            let (mean, sd, valid) = stats(&d);
            assert_eq!(valid, 1.0, "wall at {z} m: every pixel valid");
            assert!((sd - want).abs() < 0.04 * want, "sd at {z} m: {sd}, model {want}");
            // Unbiased: within 4 standard errors of the mean.
            let se = want / (d.len() as f64).sqrt();
            assert!((mean - f64::from(z)).abs() < 4.0 * se, "unbiased at {z} m: {mean}");
        }
        assert!((StereoDepth::GEMINI_305.sigma_m(0.5) - 0.005).abs() < 1e-12);
        // Nearer than the minimum range: nothing.
        let mut near = vec![0.03f32; 100];
        orbbec(5).draw(2).apply_depth(&mut near, &intr(10, 10, 10.0));
        assert!(near.iter().all(|z| *z == 0.0));
    }

    #[test]
    fn orbbec_edges_and_shadows_are_invalid() {
        // A 20x20 px box at 0.5 m in front of a wall at 1 m, f = 400 px. The second IR camera
        // (18 mm to the right) cannot see the wall for 400 * 0.018 * (1/0.5 - 1/1) = 7.2 px left
        // of the box; right of the box only the edge pixel goes.
        let (w, h) = (64usize, 48usize);
        let k = intr(w as u32, h as u32, 400.0);
        let mut d = vec![1.0f32; w * h];
        for v in 14..34 {
            for u in 22..42 {
                d[v * w + u] = 0.5;
            }
        }
        orbbec(1).draw(0).apply_depth(&mut d, &k);
        let at = |u: usize, v: usize| d[v * w + u];
        let row = 24;
        // Edges: both sides of the box's outline.
        for u in [21, 22, 41, 42] {
            assert_eq!(at(u, row), 0.0, "edge pixel {u}");
        }
        assert_eq!(at(30, 13), 0.0, "top edge, wall side");
        assert_eq!(at(30, 14), 0.0, "top edge, box side");
        // The box and the wall away from it keep depth near the truth.
        assert!((at(30, row) - 0.5).abs() < 0.05, "box {}", at(30, row));
        assert!((at(50, row) - 1.0).abs() < 0.1, "wall right of the box {}", at(50, row));
        assert!((at(5, row) - 1.0).abs() < 0.1, "wall far left {}", at(5, row));
        // The shadow: the wall left of the box, 7 px wide; not on the right.
        for u in 15..21 {
            assert_eq!(at(u, row), 0.0, "shadow pixel {u}");
        }
        assert!(at(13, row) > 0.0, "past the shadow");
        for u in 43..48 {
            assert!(at(u, row) > 0.0, "no shadow right of the box at {u}");
        }
    }

    #[test]
    fn orbbec_grazing_surfaces_are_invalid() {
        // A plane turned theta about the camera's y axis: n = (sin, 0, cos), n.X = d0.
        let (w, h) = (32usize, 24usize);
        let k = intr(w as u32, h as u32, 400.0);
        let plane = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            let mut d = vec![0.0f32; w * h];
            for v in 0..h {
                for u in 0..w {
                    let x = (u as f64 - k.cx) / k.fx;
                    d[v * w + u] = (0.05 / (s * x + c)) as f32;
                }
            }
            orbbec(9).draw(1).apply_depth(&mut d, &k);
            stats(&d).2
        };
        assert_eq!(plane(60.0), 1.0, "60 deg: all valid");
        assert!(plane(86.0) < 0.05, "86 deg: {} valid", plane(86.0));
    }

    #[test]
    fn orbbec_noise_is_the_same_for_a_seed_and_capture_only() {
        let k = intr(40, 30, 40.0);
        let render = |seed: u64, tick: u64| {
            let mut d = vec![0.8f32; 40 * 30];
            orbbec(seed).draw(tick).apply_depth(&mut d, &k);
            d
        };
        assert_eq!(render(3, 10), render(3, 10));
        assert_ne!(render(3, 10), render(4, 10));
        assert_ne!(render(3, 10), render(3, 11));
        let ideal = {
            let mut d = vec![0.8f32; 40 * 30];
            NoiseModel::default().draw(1).apply_depth(&mut d, &k);
            d
        };
        assert!(ideal.iter().all(|z| *z == 0.8), "ideal leaves depth alone");
    }
}
