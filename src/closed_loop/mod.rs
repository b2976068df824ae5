//! `hitl run --closed-loop`: the chaser holds its planned relative state on what it sees.
//!
//! Every pose estimate of the perception worker becomes a measurement of the chaser's deviation
//! from its plan in the plan's relative frame; a Kalman filter predicted with the HCW model
//! smooths and gates them; guidance turns the filtered deviation into a camera correction inside
//! a corridor around the preflighted plan, and that into a joint offset of the upcoming
//! setpoints, moved to with Ruckig and checked by the preflight's rules before the tick may use
//! it. All of it runs on the navigator's thread; the tick only adds a prepared offset
//! (`crate::control::correction`). docs/closed-loop.md says what is and is not proven.
//!
//! - [`filter`]: the relative-navigation filter (HCW prediction, Mahalanobis gate);
//! - [`guidance`]: deviation to camera correction to joint offset;
//! - [`corridor`]: the bound on a correction, and its check;
//! - [`segment`]: a correction as the tick plays it (Ruckig moves), checked;
//! - [`navigator`]: the thread that ties them to the run: estimates in, segments and records out;
//! - [`lockstep`]: on a simulated clock, the navigator's turns between the loop's ticks.

pub mod corridor;
pub mod filter;
pub mod guidance;
pub mod lockstep;
pub mod navigator;
pub mod segment;

use hitl_trajectories::Trajectory;
use nalgebra::{Matrix3, Vector3};

/// The plan's relative frame as its metadata gives it (docs/planner.md, "Lab mapping"):
/// `camera (base) = target (base) + scale * rtn_to_base * rel_pos_rtn`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanFrame {
    /// Lab metres per real metre.
    pub scale: f64,
    /// `v_base = rtn_to_base * v_rtn`.
    pub rtn_to_base: Matrix3<f64>,
    /// Where the plan put the target (base frame, lab metres).
    pub target_base_m: Vector3<f64>,
    /// Orbit seconds per playback second (the plan's, times `--speed-scale`).
    pub time_scale: f64,
    /// The chief's mean motion, rad/s.
    pub mean_motion_rad_s: f64,
}

impl PlanFrame {
    /// The frame of a planned trajectory played at `speed_scale`, or why it has none (a file
    /// not written by `hitl plan`, or metadata without a usable frame).
    pub fn from_plan(traj: &Trajectory, speed_scale: f64) -> Result<Self, String> {
        let why = |what: &str| {
            format!(
                "--closed-loop needs a planned trajectory (`hitl plan`): its metadata {what} \
                 (docs/closed-loop.md)"
            )
        };
        let text = traj.meta.as_deref().ok_or_else(|| why("is missing"))?;
        let meta: serde_json::Value = serde_json::from_str(text).map_err(|_| why("is not JSON"))?;
        let num = |key: &str| {
            meta.get(key)
                .and_then(|v| v.as_f64())
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| why(&format!("has no positive `{key}`")))
        };
        let rtn_to_base = hitl_trajectories::planner::rtn_to_base(traj)
            .ok_or_else(|| why("has no rotation `rtn_to_base`"))?;
        let target = meta
            .get("target_pos_base_m")
            .and_then(|v| v.as_array())
            .filter(|a| a.len() == 3)
            .and_then(|a| {
                let v: Option<Vec<f64>> = a.iter().map(|x| x.as_f64()).collect();
                v.map(|v| Vector3::new(v[0], v[1], v[2]))
            })
            .ok_or_else(|| why("has no `target_pos_base_m`"))?;
        Ok(Self {
            scale: num("scale")?,
            rtn_to_base,
            target_base_m: target,
            time_scale: num("time_scale")? * speed_scale,
            mean_motion_rad_s: num("mean_motion_rad_s")?,
        })
    }

    /// A lab vector (base frame, metres) in the plan's frame (RTN, real metres).
    pub fn lab_to_rtn(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.rtn_to_base.transpose() * v / self.scale
    }

    /// A plan-frame vector (RTN, real metres) in the lab (base frame, metres).
    pub fn rtn_to_lab(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rtn_to_base * v)
    }
}

/// How the closed loop behaves (`hitl run --closed-loop`'s flags and the documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedLoopConfig {
    /// `--corridor-m`: how far a correction may move the camera from the plan (lab metres).
    pub corridor_m: f64,
    /// An estimate whose exposure is older than this when it arrives is late, not used.
    pub max_age_s: f64,
    /// This many unusable captures in a row (lost, late, gated, missing) end the closed loop:
    /// back to the plan, with a recorded event.
    pub fallback_after: u32,
    /// A correction holds this long after its move, then returns to the plan unless a newer
    /// one replaced it.
    pub hold_s: f64,
    /// `--drill-perception-stop-s`: stop the perception worker this many seconds into the
    /// playback (a drill of the fallback).
    pub drill_perception_stop_s: Option<f64>,
    /// `--drill-perception-offset-m M --drill-perception-offset-s S`: from `S` seconds into the
    /// playback, every estimate the navigator takes is moved `M` (lab metres) along the camera's
    /// x axis (a drill of the gate: a perception that lies).
    pub drill_perception_offset: Option<EstimateOffsetDrill>,
}

/// A drill of the gate: estimates moved by a fixed offset from a time on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateOffsetDrill {
    /// How far, lab metres, along the camera's x axis.
    pub offset_m: f64,
    /// From this many seconds into the playback.
    pub from_s: f64,
}

impl EstimateOffsetDrill {
    /// The drill, or why its flags are unusable.
    pub fn new(offset_m: f64, from_s: f64) -> Result<Self, String> {
        if !offset_m.is_finite() || offset_m.abs() > 1.0 {
            return Err(format!(
                "--drill-perception-offset-m must be a distance within 1 m, not {offset_m}"
            ));
        }
        if !from_s.is_finite() || from_s < 0.0 {
            return Err(format!(
                "--drill-perception-offset-s must be 0 or more seconds, not {from_s}"
            ));
        }
        Ok(Self { offset_m, from_s })
    }
}

impl Default for ClosedLoopConfig {
    fn default() -> Self {
        Self {
            corridor_m: corridor::DEFAULT_CORRIDOR_M,
            max_age_s: 1.0,
            fallback_after: 5,
            hold_s: 1.5,
            drill_perception_stop_s: None,
            drill_perception_offset: None,
        }
    }
}
