//! Back-projection of the target's depth pixels into a camera-frame point cloud.

use crate::PerceptionFrame;
use nalgebra::Vector3;

/// The target's pixels of a frame, as the tracker uses them.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// Camera-frame points, at most the number asked, at a regular stride over the target
    /// pixels so the sample is deterministic and spread out.
    pub points: Vec<Vector3<f64>>,
    /// The depth noise's standard deviation at the target, metres, estimated from the frame
    /// itself (0 when it cannot be: too few neighbouring target pixels).
    pub noise_m: f64,
    /// The points' own depth noise, metres: `noise_m` over the square root of the depths each
    /// point averages ([`Smoothing`]); `noise_m` without smoothing.
    pub point_noise_m: f64,
    /// Depth beyond which a mask pixel is not the target's (behind its outline): infinite
    /// without a mask.
    pub far_m: f64,
}

/// Camera-frame points of the target pixels (mask and valid depth), at most `max_points`.
///
/// With a mask, pixels whose depth lies more than `depth_window` (the target's size) behind
/// the nearest part of the target are dropped: a mask that is not the target's exact silhouette
/// (drawn from a calibrated lab with a margin, [`crate::silhouette`]) also covers what lies
/// behind the target's outline (curtains, the stand), and a stereo camera's depth there is not
/// the target's. The nearest part is the 10th percentile of the mask's depths (robust to a few
/// stray near pixels).
pub fn scene(
    frame: &PerceptionFrame,
    max_points: usize,
    depth_window: f64,
    smoothing: &Smoothing,
) -> Scene {
    let k = &frame.intrinsics;
    let w = k.width as usize;
    let mut idx: Vec<usize> = (0..frame.depth_m.len()).filter(|&i| frame.is_target(i)).collect();
    let mut far_m = f64::INFINITY;
    if frame.mask.is_some() && depth_window > 0.0 && idx.len() > 10 {
        let mut z: Vec<f32> = idx.iter().map(|&i| frame.depth_m[i]).collect();
        let p10 = idx.len() / 10;
        let (_, near, _) = z.select_nth_unstable_by(p10, f32::total_cmp);
        let far = f64::from(*near) + depth_window;
        idx.retain(|&i| f64::from(frame.depth_m[i]) <= far);
        far_m = far;
    }
    let stride = idx.len().div_ceil(max_points.max(1)).max(1);
    let noise = depth_noise(frame, &idx, stride);
    let mut averaged = 0usize;
    let mut counted = 0usize;
    let points = idx
        .iter()
        .step_by(stride)
        .filter_map(|&i| {
            let (u, v) = (i % w, i / w);
            let z = match smoothing.smoothed(frame, u, v, noise, far_m) {
                Smoothed::Depth(z, n) => {
                    averaged += n;
                    counted += 1;
                    z
                }
                Smoothed::Edge => return None,
                Smoothed::Off => f64::from(frame.depth_m[i]),
            };
            let (u, v) = (u as f64, v as f64);
            let (x, y) = k.unproject(u, v);
            Some(Vector3::new(x * z, y * z, z))
        })
        .collect();
    // The points' own noise: the pixel's over the square root of the depths averaged.
    let point_noise_m =
        if counted > 0 { noise / (averaged as f64 / counted as f64).sqrt() } else { noise };
    Scene { points, noise_m: noise, point_noise_m, far_m }
}

/// How the depth of a scene point is taken from its neighbourhood: the mean of the target depths
/// in a `(2 radius + 1)^2` window that lie within `gate_sigmas` of the frame's noise of the
/// centre's (the range part of a bilateral filter, as KinectFusion filters its depth maps before
/// ICP): a stereo camera's per-pixel error averages down over a surface patch while depths of
/// another surface (a depth edge, what lies behind the outline) are left out. A pixel whose
/// window holds fewer than `min_fill` of target depths on its own surface is at an edge or beside
/// a shadow (a stereo camera's depth there is the least reliable) and is not used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Smoothing {
    /// Window half-size, pixels; 0 takes each pixel's depth as it is.
    pub radius: usize,
    pub gate_sigmas: f64,
    pub min_fill: f64,
}

impl Smoothing {
    /// Each pixel's depth as it is.
    pub const OFF: Smoothing = Smoothing { radius: 0, gate_sigmas: 0.0, min_fill: 0.0 };
}

enum Smoothed {
    /// The window's mean depth and how many depths it averaged.
    Depth(f64, usize),
    /// Too few depths of the centre's surface around it.
    Edge,
    Off,
}

impl Smoothing {
    fn smoothed(
        &self,
        frame: &PerceptionFrame,
        u: usize,
        v: usize,
        noise: f64,
        far_m: f64,
    ) -> Smoothed {
        if self.radius == 0 {
            return Smoothed::Off;
        }
        let k = &frame.intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        let z0 = f64::from(frame.depth_m[v * w + u]);
        // On ideal depth the noise is ~0: the gate still admits a smooth surface's own slope.
        let gate = (self.gate_sigmas * noise).max(1e-3 * z0);
        let r = self.radius;
        let (mut sum, mut n, mut cells) = (0.0, 0usize, 0usize);
        for vv in v.saturating_sub(r)..=(v + r).min(h - 1) {
            for uu in u.saturating_sub(r)..=(u + r).min(w - 1) {
                cells += 1;
                let j = vv * w + uu;
                if !frame.is_target(j) {
                    continue;
                }
                let z = f64::from(frame.depth_m[j]);
                if z <= far_m && (z - z0).abs() <= gate {
                    sum += z;
                    n += 1;
                }
            }
        }
        if (n as f64) < self.min_fill * cells as f64 || n == 0 {
            return Smoothed::Edge;
        }
        Smoothed::Depth(sum / n as f64, n)
    }
}

/// Camera-frame points of the target pixels (see [`scene`], no depth window).
pub fn scene_points(frame: &PerceptionFrame, max_points: usize) -> Vec<Vector3<f64>> {
    scene(frame, max_points, 0.0, &Smoothing::OFF).points
}

/// The depth noise at the target pixels `idx` (every `stride`-th looked at), metres: a robust
/// standard deviation of the second difference of depth along rows, over pixels whose two
/// row neighbours are target pixels too. On a surface the second difference is (nearly) zero; a
/// sensor's independent per-pixel error e gives e(u-1) - 2 e(u) + e(u+1), whose standard
/// deviation is sqrt(6) times the error's. Median absolute value / 0.6745 is the robust sigma
/// (edges and creases are its outliers). A stereo camera's error grows as z^2: this is its value
/// at the target's range, which is what the tracker's tolerances need.
fn depth_noise(frame: &PerceptionFrame, idx: &[usize], stride: usize) -> f64 {
    let w = frame.intrinsics.width as usize;
    let mut d2: Vec<f64> = idx
        .iter()
        .step_by(stride.max(1).div_ceil(2))
        .filter(|&&i| {
            i % w > 0 && i % w + 1 < w && frame.is_target(i - 1) && frame.is_target(i + 1)
        })
        .map(|&i| {
            let z = |j: usize| f64::from(frame.depth_m[j]);
            (z(i - 1) - 2.0 * z(i) + z(i + 1)).abs()
        })
        .collect();
    if d2.len() < 20 {
        return 0.0;
    }
    let mid = d2.len() / 2;
    let (_, med, _) = d2.select_nth_unstable_by(mid, f64::total_cmp);
    *med / 0.6745 / 6f64.sqrt()
}

/// Every `step`-th point of a cloud (at least `min` points if the cloud has them).
pub fn thin(points: &[Vector3<f64>], max_points: usize) -> Vec<Vector3<f64>> {
    let stride = points.len().div_ceil(max_points.max(1)).max(1);
    points.iter().step_by(stride).copied().collect()
}

/// Mean of a cloud.
pub fn centroid(points: &[Vector3<f64>]) -> Vector3<f64> {
    if points.is_empty() {
        return Vector3::zeros();
    }
    points.iter().sum::<Vector3<f64>>() / points.len() as f64
}
