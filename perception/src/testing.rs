//! A small z-buffer rasteriser for tests and benchmarks: renders a mesh at a pose into depth
//! (metres, OpenCV pinhole, pixel centres at integer coordinates), a mask and a flat-shaded
//! colour image. Not a camera model: no noise, no lens distortion, no anti-aliasing.

use crate::models::Mesh;
use crate::PerceptionFrame;
use hitl_hal::{Intrinsics, Pose};
use nalgebra::{Translation3, UnitQuaternion, Vector3};

/// Intrinsics of a pinhole camera with a horizontal field of view of `hfov_deg`.
pub fn intrinsics_hfov(width: u32, height: u32, hfov_deg: f64) -> Intrinsics {
    let fx = 0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan();
    Intrinsics {
        width,
        height,
        fx,
        fy: fx,
        cx: (width as f64 - 1.0) / 2.0,
        cy: (height as f64 - 1.0) / 2.0,
        distortion: Default::default(),
    }
}

/// Renders `mesh` placed at `pose` (target in camera). Depth 0 and mask 0 where the target is not.
pub fn render(mesh: &Mesh, pose: &Pose, k: &Intrinsics, timestamp_ns: u64) -> PerceptionFrame {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut depth = vec![f32::INFINITY; w * h];
    let mut color = vec![0u8; w * h * 3];
    let r = pose.rotation.to_rotation_matrix();
    let t = pose.translation.vector;
    let cam: Vec<Vector3<f64>> =
        mesh.vertices().iter().map(|v| r * Vector3::new(v[0], v[1], v[2]) + t).collect();
    let light = Vector3::new(0.3, -0.5, -1.0).normalize();
    for f in mesh.faces() {
        let p = [cam[f[0] as usize], cam[f[1] as usize], cam[f[2] as usize]];
        if p.iter().any(|q| q.z <= 1e-6) {
            continue;
        }
        let uv: Vec<(f64, f64)> = p.iter().map(|q| k.project(q.x, q.y, q.z)).collect();
        let area = edge(uv[0], uv[1], uv[2]);
        if area.abs() < 1e-12 {
            continue;
        }
        let n = (p[1] - p[0]).cross(&(p[2] - p[0])).normalize();
        let shade = (40.0 + 200.0 * n.dot(&light).abs()).min(255.0) as u8;
        let umin = uv.iter().map(|a| a.0).fold(f64::INFINITY, f64::min).ceil().max(0.0) as usize;
        let vmin = uv.iter().map(|a| a.1).fold(f64::INFINITY, f64::min).ceil().max(0.0) as usize;
        let umax = uv.iter().map(|a| a.0).fold(f64::NEG_INFINITY, f64::max).floor();
        let vmax = uv.iter().map(|a| a.1).fold(f64::NEG_INFINITY, f64::max).floor();
        if umax < 0.0 || vmax < 0.0 {
            continue;
        }
        let umax = (umax as usize).min(w - 1);
        let vmax = (vmax as usize).min(h - 1);
        for v in vmin..=vmax {
            for u in umin..=umax {
                let q = (u as f64, v as f64);
                let b0 = edge(uv[1], uv[2], q) / area;
                let b1 = edge(uv[2], uv[0], q) / area;
                let b2 = edge(uv[0], uv[1], q) / area;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                // Perspective-correct depth: 1/z is affine in screen space.
                let inv_z = b0 / p[0].z + b1 / p[1].z + b2 / p[2].z;
                let z = (1.0 / inv_z) as f32;
                let idx = v * w + u;
                if z < depth[idx] {
                    depth[idx] = z;
                    color[idx * 3..idx * 3 + 3].copy_from_slice(&[shade, shade, shade]);
                }
            }
        }
    }
    let mask: Vec<u8> = depth.iter().map(|d| if d.is_finite() { 255 } else { 0 }).collect();
    for d in &mut depth {
        if !d.is_finite() {
            *d = 0.0;
        }
    }
    PerceptionFrame {
        timestamp_ns,
        seq: 0,
        intrinsics: *k,
        color: color.into(),
        depth_m: depth.into(),
        mask: Some(mask.into()),
    }
}

fn edge(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// A pose that looks at the target from `range` metres along the camera's +z, with the target
/// rotated by `roll, pitch, yaw` (radians, XYZ order).
pub fn look_pose(range: f64, roll: f64, pitch: f64, yaw: f64) -> Pose {
    let r = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    Pose::from_parts(Translation3::new(0.0, 0.0, range), r)
}
