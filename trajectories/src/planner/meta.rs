//! The `meta` JSON of a planned trajectory: every input needed to reproduce the plan and to map
//! recorded frames back to real metres. Fields are written in a fixed order and hold no clock or
//! version, so the same plan gives the same bytes. [`rtn_to_base`] reads the plan's rotation back.

use super::{OrbitPath, PlanRequest, ScaleSource, Timing};
use crate::lab::LabConfig;
use crate::orbit::MU_EARTH;
use crate::Trajectory;
use nalgebra::Matrix3;
use serde::Serialize;

#[derive(Serialize)]
struct Meta<'a> {
    generator: &'static str,
    preset: &'a str,
    range_m: f64,
    a_m: f64,
    e: f64,
    i_deg: f64,
    raan_deg: f64,
    argp_deg: f64,
    nu0_deg: f64,
    mu_m3_s2: f64,
    mean_motion_rad_s: f64,
    /// delta a, delta lambda, delta e_x, delta e_y, delta i_x, delta i_y.
    roe: [f64; 6],
    u0_rad: f64,
    arc_u_rad: [f64; 2],
    revolutions: usize,
    windup: &'static str,
    /// Lab metres per real metre.
    scale: f64,
    scale_source: &'static str,
    alpha: f64,
    d_arm_m: f64,
    time_scale: f64,
    cruise_s_per_pass: f64,
    ramp_s: f64,
    target_pos_base_m: [f64; 3],
    /// Row-major: v_base = rtn_to_base * v_rtn.
    rtn_to_base: [[f64; 3]; 3],
    /// Row-major flange-to-camera transform (camera in OpenCV axes).
    camera_mount: [[f64; 4]; 4],
    camera_up_reference_base: [f64; 3],
    sun_eci: [f64; 3],
    sun_phase_axis: &'static str,
    light: f32,
    capture_every: usize,
}

pub(super) fn meta_json(req: &PlanRequest, lab: &LabConfig, path: &OrbitPath) -> String {
    let c = &req.chief;
    let n = c.mean_motion();
    let time_scale = match req.timing {
        Timing::TimeScale(s) => s,
        Timing::DurationS(_) => path.schedule.span / (n * path.schedule.cruise_s),
    };
    let m = &path.rtn_to_base;
    let meta = Meta {
        generator: "hitl plan",
        preset: req.preset.name(),
        range_m: req.range_m,
        a_m: c.a_m,
        e: c.e,
        i_deg: c.i_deg,
        raan_deg: c.raan_deg,
        argp_deg: c.argp_deg,
        nu0_deg: c.nu0_deg,
        mu_m3_s2: MU_EARTH,
        mean_motion_rad_s: n,
        roe: path.roe.0,
        u0_rad: path.u0,
        arc_u_rad: [path.schedule.u_start, path.schedule.u_start + path.schedule.span],
        revolutions: path.schedule.passes,
        windup: "direction alternates after each pass",
        scale: path.scale,
        scale_source: match path.scale_source {
            ScaleSource::Workspace => "alpha * d_arm / range_m",
            ScaleSource::Model => "target.model_size_m / target.real_size_m",
        },
        alpha: req.alpha,
        d_arm_m: req.d_arm_m,
        time_scale,
        cruise_s_per_pass: path.schedule.cruise_s,
        ramp_s: path.schedule.ramp_s,
        target_pos_base_m: path.target_base.coords.into(),
        rtn_to_base: [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
        ],
        camera_mount: super::pose_rows(&lab.camera_mount()),
        camera_up_reference_base: path.up_base.into(),
        sun_eci: req.sun_eci,
        sun_phase_axis: "chief orbit normal N: (sun x chaser).N >= 0 gives 0-180",
        light: req.light,
        capture_every: req.capture_every,
    };
    serde_json::to_string(&meta).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
}

/// The trajectory's RTN-to-base rotation (`meta.rtn_to_base`, rows, `v_base = M v_rtn`), if
/// its metadata has a finite one.
pub fn rtn_to_base(traj: &Trajectory) -> Option<Matrix3<f64>> {
    let meta: serde_json::Value = serde_json::from_str(traj.meta.as_deref()?).ok()?;
    let rows = meta.get("rtn_to_base")?.as_array()?;
    let mut m = Matrix3::zeros();
    for (r, row) in rows.iter().enumerate().take(3) {
        for (c, v) in row.as_array()?.iter().enumerate().take(3) {
            m[(r, c)] = v.as_f64()?;
        }
    }
    // A rotation: finite and orthonormal (else the file's metadata is not the planner's).
    let ok = rows.len() == 3
        && m.iter().all(|x| x.is_finite())
        && (m.transpose() * m - Matrix3::identity()).norm() < 1e-6;
    ok.then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_plans_rotation_is_read_from_its_metadata() {
        let mut traj = Trajectory {
            meta: Some(r#"{"rtn_to_base":[[0,1,0],[-1,0,0],[0,0,1]]}"#.into()),
            ..Trajectory::default()
        };
        let m = rtn_to_base(&traj).expect("rotation");
        assert_eq!(m * Vector3::x(), Vector3::new(0.0, -1.0, 0.0));
        traj.meta = Some(r#"{"rtn_to_base":[[2,0,0],[0,1,0],[0,0,1]]}"#.into());
        assert_eq!(rtn_to_base(&traj), None, "not a rotation");
        traj.meta = Some("{}".into());
        assert_eq!(rtn_to_base(&traj), None);
    }
}
