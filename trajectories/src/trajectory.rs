//! The in-memory trajectory: the NPZ schema of docs/architecture.md as typed Rust data.
//!
//! Loading and writing live in [`crate::npz`]; validation of values in [`crate::npz`] as well
//! (every array is checked against `qpos`'s waypoint count when it is read).

use crate::kinematics::Joints;

/// A joint trajectory with its optional capture, light and planner channels.
/// Every per-waypoint vector has the same length as `qpos`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectory {
    /// Joint positions, radians, one row per waypoint (`qpos`, (N,7)).
    pub qpos: Vec<Joints>,
    /// Seconds from 0, strictly increasing (`t`, (N,)).
    pub t: Vec<f64>,
    /// Capture a frame at this waypoint (`capture`, (N,) bool).
    pub capture: Option<Vec<bool>>,
    /// Light level schedule in [0, 1] (`light`, (N,) float32).
    pub light: Option<Vec<f32>>,
    /// Chief argument of latitude (`u_rad`, (N,)).
    pub u_rad: Option<Vec<f64>>,
    /// Chaser position relative to target, RTN, real metres (`rel_pos_rtn_m`, (N,3)).
    pub rel_pos_rtn_m: Option<Vec<[f64; 3]>>,
    /// Planned camera pose in the base frame, OpenCV axes, row-major 4x4 (`cam_pose_base`, (N,4,4)).
    pub cam_pose_base: Option<Vec<[[f64; 4]; 4]>>,
    /// Oriented Sun phase angle, degrees, 0-360 (`sun_phase_deg`, (N,)).
    pub sun_phase_deg: Option<Vec<f64>>,
    /// JSON metadata (`meta`, 0-d str).
    pub meta: Option<String>,
}

impl Trajectory {
    /// Number of waypoints.
    pub fn len(&self) -> usize {
        self.qpos.len()
    }

    pub fn is_empty(&self) -> bool {
        self.qpos.is_empty()
    }

    /// Duration in seconds (last `t`), 0 when empty.
    pub fn duration(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }

    /// Number of waypoints flagged for capture.
    pub fn capture_count(&self) -> usize {
        self.capture.as_ref().map_or(0, |c| c.iter().filter(|x| **x).count())
    }
}
