//! Global registration: a grid of rotation hypotheses (viewpoints on a Fibonacci sphere times
//! in-plane angles), each placed so the model's camera-facing surface sits on the scene centroid,
//! briefly refined on a thinned cloud; the best few are refined fully and scored in the image.

use super::model::ModelCloud;
use nalgebra::{Matrix3, Vector3};

/// Rotations (body to camera) covering SO(3): `views` viewing directions times `inplane` rolls.
pub fn rotation_grid(views: usize, inplane: usize) -> Vec<Matrix3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut out = Vec::with_capacity(views * inplane);
    for i in 0..views {
        let y = 1.0 - 2.0 * (i as f64 + 0.5) / views as f64;
        let rad = (1.0 - y * y).max(0.0).sqrt();
        let th = golden * i as f64;
        // Direction from the target to the camera, body frame.
        let d = Vector3::new(rad * th.cos(), y, rad * th.sin());
        let z = -d; // camera forward, body frame
        let helper = if z.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let x0 = helper.cross(&z).normalize();
        let y0 = z.cross(&x0);
        for j in 0..inplane {
            let a = std::f64::consts::TAU * j as f64 / inplane as f64;
            let x = x0 * a.cos() + y0 * a.sin();
            let yy = z.cross(&x);
            // Rows are the camera axes expressed in the body frame.
            out.push(Matrix3::from_rows(&[x.transpose(), yy.transpose(), z.transpose()]));
        }
    }
    out
}

/// Centroid of the camera-facing surface of the model rotated by `r` (front-most sample in each
/// cell of a 16 x 16 grid across the image plane), in rotated (camera-aligned) coordinates.
pub fn front_centroid(model: &ModelCloud, r: &Matrix3<f64>) -> Vector3<f64> {
    const N: usize = 16;
    let half = 0.5 * model.diameter;
    let mut best: [Option<Vector3<f64>>; N * N] = [None; N * N];
    for p in &model.points {
        let q = r * p;
        let cx = (((q.x + half) / (2.0 * half)) * N as f64).clamp(0.0, N as f64 - 1.0) as usize;
        let cy = (((q.y + half) / (2.0 * half)) * N as f64).clamp(0.0, N as f64 - 1.0) as usize;
        let cell = &mut best[cy * N + cx];
        if cell.is_none_or(|b| q.z < b.z) {
            *cell = Some(q);
        }
    }
    let (sum, n) =
        best.iter().flatten().fold((Vector3::zeros(), 0usize), |(s, n), q| (s + q, n + 1));
    if n == 0 {
        Vector3::zeros()
    } else {
        sum / n as f64
    }
}
