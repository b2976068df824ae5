//! The corridor: how far (lab metres) a correction may move the camera from where the
//! preflighted plan puts it at the same tick. Guidance clamps what it asks for to it, and every
//! corrected setpoint of a correction segment is measured against it (forward kinematics of the
//! corrected and of the planned joints) before the segment may go to the tick.

use hitl_hal::{Joints, Pose};
use hitl_trajectories::kinematics::camera_pose;
use nalgebra::Vector3;

/// `--corridor-m`'s default: 6 mm of lab.
pub const DEFAULT_CORRIDOR_M: f64 = 0.006;

/// The corridor around the plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corridor {
    /// Radius, lab metres.
    pub radius_m: f64,
}

impl Corridor {
    /// A corridor of `radius_m` (finite, > 0, and under 5 cm: a correction, not a new plan).
    pub fn new(radius_m: f64) -> Result<Self, String> {
        if !radius_m.is_finite() || radius_m <= 0.0 || radius_m > 0.05 {
            return Err(format!(
                "--corridor-m must be a finite number of metres in (0, 0.05], got {radius_m}"
            ));
        }
        Ok(Self { radius_m })
    }

    /// `wanted` shortened to the corridor's radius (direction kept); whether it was shortened.
    pub fn clamp(&self, wanted: &Vector3<f64>) -> (Vector3<f64>, bool) {
        let norm = wanted.norm();
        if !norm.is_finite() {
            return (Vector3::zeros(), true);
        }
        if norm <= self.radius_m {
            (*wanted, false)
        } else {
            (wanted * (self.radius_m / norm), true)
        }
    }

    /// How far the camera at `corrected` is from the camera at `planned` (lab metres).
    pub fn displacement(planned: &Joints, corrected: &Joints, mount: &Pose) -> f64 {
        let a = camera_pose(planned, mount).translation.vector;
        let b = camera_pose(corrected, mount).translation.vector;
        (b - a).norm()
    }

    /// Whether the corrected joints keep the camera inside the corridor (with 1 um for rounding).
    pub fn contains(&self, planned: &Joints, corrected: &Joints, mount: &Pose) -> bool {
        Self::displacement(planned, corrected, mount) <= self.radius_m + 1e-6
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_trajectories::lab::LabConfig;

    #[test]
    fn clamps_to_the_radius_and_refuses_bad_radii() {
        let c = Corridor::new(0.003).expect("valid");
        let (v, shortened) = c.clamp(&Vector3::new(0.004, 0.0, 0.003));
        assert!(shortened);
        assert!((v.norm() - 0.003).abs() < 1e-12);
        assert!((v.x / v.z - 4.0 / 3.0).abs() < 1e-9, "direction kept");
        let (v, shortened) = c.clamp(&Vector3::new(0.001, 0.0, 0.0));
        assert!(!shortened);
        assert_eq!(v.x, 0.001);
        assert_eq!(c.clamp(&Vector3::new(f64::NAN, 0.0, 0.0)).0, Vector3::zeros());
        for bad in [0.0, -0.001, f64::NAN, 0.2] {
            assert!(Corridor::new(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn contains_measures_the_camera_not_the_joints() {
        let lab = LabConfig::default();
        let mount = lab.camera_mount();
        let q = lab.arm.rest_q;
        let c = Corridor::new(0.003).expect("valid");
        let mut moved = q;
        moved[0] += 0.001; // ~0.5 mm at the camera
        assert!(c.contains(&q, &moved, &mount));
        moved[0] += 0.02; // ~1 cm
        assert!(!c.contains(&q, &moved, &mount));
    }
}
