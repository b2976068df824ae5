//! Back-projection of the target's depth pixels into a camera-frame point cloud.

use crate::PerceptionFrame;
use nalgebra::Vector3;

/// Camera-frame points of the target pixels (mask and valid depth), at most `max_points`, taken
/// at a regular stride over the target pixels so the sample is deterministic and spread out.
pub fn scene_points(frame: &PerceptionFrame, max_points: usize) -> Vec<Vector3<f64>> {
    let k = &frame.intrinsics;
    let w = k.width as usize;
    let idx: Vec<usize> = (0..frame.depth_m.len()).filter(|&i| frame.is_target(i)).collect();
    let stride = idx.len().div_ceil(max_points.max(1)).max(1);
    idx.iter()
        .step_by(stride)
        .map(|&i| {
            let z = frame.depth_m[i] as f64;
            let (u, v) = ((i % w) as f64, (i / w) as f64);
            Vector3::new((u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z)
        })
        .collect()
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
