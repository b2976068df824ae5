//! The stub's Sun: `--light sim` sets the level the simulated camera shades with
//! ([`SimLight`]), and [`sun_schedule`] turns a trajectory's Sun phase into the direction the
//! `orbit` scene's sunlight travels at each waypoint (docs/stub-scene.md).

use hitl_hal::{ErrorKind, ErrorType, Lifecycle, Light};
use hitl_trajectories::kinematics::camera_pose;
use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::planner::mapping;
use hitl_trajectories::timing::SetpointTable;
use hitl_trajectories::Trajectory;
use nalgebra::Vector3;

/// Sets the simulated Sun's level (lock-free).
#[derive(Debug, Clone)]
pub struct SimLight(pub hitl_sim_stub::camera::LightLevel);

impl ErrorType for SimLight {
    type Error = ErrorKind;
}

/// Nothing to start or stop: the level is a shared cell.
impl Lifecycle for SimLight {}

impl Light for SimLight {
    fn set_level(&mut self, level: f32) -> Result<(), ErrorKind> {
        if !(0.0..=1.0).contains(&level) {
            return Err(ErrorKind::InvalidRequest);
        }
        self.0.set(level);
        Ok(())
    }
}

/// The Sun's direction in the Hill frame's base-frame axes for a chaser in direction `rho`
/// from the target (base frame) at oriented Sun phase `phase_deg`, with orbit normal `normal`
/// (base frame): the direction at `phase_deg` from `rho` in the plane of `rho` and
/// `normal x rho`, turned the way the planner's orientation rule says (docs/planner.md: the
/// phase is the unsigned angle when (sun x chaser) . N >= 0, 360 minus it otherwise). For a
/// chaser in the chief's orbit plane this is the Sun in that plane. `None` when `rho` is zero or
/// along the normal (the phase then fixes no direction).
pub fn sun_from_phase(
    rho: &Vector3<f64>,
    normal: &Vector3<f64>,
    phase_deg: f64,
) -> Option<Vector3<f64>> {
    let r = rho.try_normalize(1e-12)?;
    let side = normal.cross(&r).try_normalize(1e-9)?;
    let (s, c) = phase_deg.to_radians().sin_cos();
    (phase_deg.is_finite()).then(|| (r * c - side * s).normalize())
}

/// The direction the `orbit` scene's sunlight travels (lab frame, unit, from the Sun towards
/// the target) at each waypoint of `traj` that has one, keyed by the waypoint's tick in
/// `table`. The chaser's direction from the target is its planned position (`rel_pos_rtn_m`
/// through the plan's RTN-to-base rotation) or, without one, the camera's by forward
/// kinematics; the orbit normal is the plan's (the planner's default rotation without
/// `meta.rtn_to_base`). Empty without `sun_phase_deg`.
pub fn sun_schedule(
    traj: &Trajectory,
    table: &SetpointTable,
    lab: &LabConfig,
) -> Vec<(u64, Vector3<f64>)> {
    let Some(phase) = &traj.sun_phase_deg else { return Vec::new() };
    let m =
        hitl_trajectories::planner::rtn_to_base(traj).unwrap_or_else(mapping::default_rtn_to_base);
    let normal = m.column(2).into_owned();
    let base = lab.base_in_lab();
    let mount = lab.camera_mount();
    let target = lab.target_position_base();
    let mut out = Vec::with_capacity(phase.len());
    for (k, &deg) in phase.iter().enumerate() {
        let Some(&tick) = table.waypoint_ticks.get(k) else { break };
        let rho = match traj.rel_pos_rtn_m.as_ref().and_then(|r| r.get(k)) {
            Some(p) => m * Vector3::from(*p),
            None => match traj.qpos.get(k) {
                Some(q) => camera_pose(q, &mount).translation.vector - target.coords,
                None => break,
            },
        };
        if let Some(sun) = sun_from_phase(&rho, &normal, deg) {
            out.push((tick as u64, -(base.rotation * sun)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_trajectories::orbit::{sun_phase_deg, ChiefOrbit};

    /// The planner's phase of a Sun, turned back into a direction, is that Sun (for a chaser
    /// and Sun in the orbit plane), on both sides of the chaser.
    #[test]
    fn the_phase_gives_back_the_planners_sun() {
        let chief = ChiefOrbit::default();
        let n = Vector3::z();
        let cases: [(f64, [f64; 3], f64); 3] = [
            (0.3, [1.0, 2.0, 0.0], 0.7),
            (2.0, [-3.0, 0.5, 0.0], -2.2),
            (4.0, [0.0, -1.0, 0.0], 3.0),
        ];
        for (u, rho, sun_angle) in cases {
            let rho = Vector3::from(rho);
            let sun_rtn = Vector3::new(sun_angle.cos(), sun_angle.sin(), 0.0);
            let sun_eci: Vector3<f64> = chief.rtn_to_eci(u) * sun_rtn;
            let phase = sun_phase_deg(&chief, u, &rho, &sun_eci).expect("phase");
            let back = sun_from_phase(&rho, &n, phase).expect("direction");
            assert!((back - sun_rtn).norm() < 1e-9, "u {u}: {back:?} want {sun_rtn:?} ({phase})");
        }
        assert_eq!(sun_from_phase(&Vector3::zeros(), &n, 10.0), None);
        assert_eq!(sun_from_phase(&n, &n, 10.0), None);
    }
}
