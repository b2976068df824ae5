//! The collision scene the IK keeps the arm away from: the lab's keep-out capsules (target,
//! tripod, light), the enclosure box, and a few non-adjacent self pairs of the arm's capsules.
//! Distances are surface to surface minus the lab's margins, so a negative clearance is a
//! violation.

use crate::geometry::Capsule;
use crate::kinematics::{arm_capsules, CameraBody, Joints, CAPSULE_NAMES};
use crate::lab::LabConfig;
use hitl_hal::Pose;
use nalgebra::Point3;

/// Self-collision pairs checked (indices into [`CAPSULE_NAMES`]): the hand, flange and camera
/// against the base column and the upper arm, and the camera against the elbow.
const SELF_PAIRS: [(usize, usize); 7] = [(0, 5), (0, 6), (0, 7), (1, 5), (1, 6), (1, 7), (2, 7)];

/// Clearance kept between the arm's own capsules, metres.
pub const SELF_MARGIN_M: f64 = 0.01;

/// The nearest thing to the arm, for reports.
#[derive(Debug, Clone, PartialEq)]
pub struct Nearest {
    /// Clearance minus margin, metres (negative: violation).
    pub clearance_m: f64,
    /// Which arm capsule.
    pub part: &'static str,
    /// Which obstacle ("target", "tripod", "light", "enclosure", or an arm capsule).
    pub obstacle: &'static str,
}

/// Obstacles in the arm-base frame.
#[derive(Debug, Clone)]
pub struct Scene {
    pub mount: Pose,
    pub camera: CameraBody,
    keepouts: Vec<(&'static str, Capsule)>,
    keepout_margin: f64,
    base_in_lab: Pose,
    box_lo: Point3<f64>,
    box_hi: Point3<f64>,
    wall_margin: f64,
}

impl Scene {
    pub fn from_lab(lab: &LabConfig) -> Self {
        let (box_lo, box_hi) = lab.enclosure_box();
        Self {
            mount: lab.camera_mount(),
            camera: lab.camera.body,
            keepouts: lab.keepouts_base().to_vec(),
            keepout_margin: lab.margins.keepout_m,
            base_in_lab: lab.base_in_lab(),
            box_lo,
            box_hi,
            wall_margin: lab.margins.wall_m,
        }
    }

    /// The smallest clearance (minus margins) of the arm at `q` to anything in the scene.
    pub fn nearest(&self, q: &Joints) -> Nearest {
        let caps = arm_capsules(q, &self.mount, &self.camera);
        let mut best = Nearest { clearance_m: f64::INFINITY, part: "", obstacle: "" };
        let mut consider = |d: f64, part: &'static str, obstacle: &'static str| {
            if d < best.clearance_m {
                best = Nearest { clearance_m: d, part, obstacle };
            }
        };
        for (i, cap) in caps.iter().enumerate() {
            let name = CAPSULE_NAMES[i];
            for (obstacle, k) in &self.keepouts {
                // The base column stands on the floor beside the tripod foot: never near.
                consider(cap.distance_to(k) - self.keepout_margin, name, obstacle);
            }
            if i == 0 {
                // The base is bolted to the floor: the enclosure check starts at the upper arm.
                continue;
            }
            let in_lab = cap.transformed(&self.base_in_lab);
            let faces = in_lab.box_clearances(&self.box_lo, &self.box_hi);
            let wall = faces.iter().copied().fold(f64::INFINITY, f64::min);
            consider(wall - self.wall_margin, name, "enclosure");
        }
        for (i, j) in SELF_PAIRS {
            consider(
                caps[i].distance_to(&caps[j]) - SELF_MARGIN_M,
                CAPSULE_NAMES[j],
                CAPSULE_NAMES[i],
            );
        }
        best
    }

    /// A smooth penalty that grows as any clearance falls under `activation_m` (0 beyond).
    pub fn penalty(&self, q: &Joints, activation_m: f64) -> f64 {
        let caps = arm_capsules(q, &self.mount, &self.camera);
        let mut p = 0.0;
        let mut add = |d: f64| {
            if d < activation_m {
                let x = (activation_m - d) / activation_m;
                p += x * x;
            }
        };
        for (i, cap) in caps.iter().enumerate() {
            for (_, k) in &self.keepouts {
                add(cap.distance_to(k) - self.keepout_margin);
            }
            if i > 0 {
                let faces =
                    cap.transformed(&self.base_in_lab).box_clearances(&self.box_lo, &self.box_hi);
                for f in faces {
                    add(f - self.wall_margin);
                }
            }
        }
        for (i, j) in SELF_PAIRS {
            add(caps[i].distance_to(&caps[j]) - SELF_MARGIN_M);
        }
        p
    }
}
