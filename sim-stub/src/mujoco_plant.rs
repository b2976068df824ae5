//! The MuJoCo plant: the lab model compiled once ([`LabModel`]), stepped at a fixed timestep by
//! the protocol server through the [`Plant`] trait, with the arm's measured state published for
//! the simulated camera ([`SharedArmState`]).
//!
//! `MjData<Arc<MjModel>>` is `Send` (mujoco-rs implements it when the model handle is `Send`, and
//! `MjModel` is `Send + Sync`), so the plant moves onto the server's thread and the camera's
//! render thread keeps its own `MjData` on the same `Arc<MjModel>`.
//!
//! A [`LabModel`] also carries the scene's kind and the run's [`SunTrack`] (the Sun's direction
//! per capture in the `orbit` scene), shared by every clone.

use crate::mjcf::{
    self, SceneOptions, TargetModel, ACTUATOR_NAMES, CAMERA_NAME, CAMERA_SITE, JOINT_NAMES,
};
use crate::plant::{Collision, Plant};
use crossbeam::atomic::AtomicCell;
use hitl_hal::{Joints, DOF};
use hitl_trajectories::lab::{LabConfig, SceneKind};
use mujoco_rs::prelude::{MjData, MjModel, MjtObjBase};
use nalgebra::Vector3;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

/// Why the stub's scene could not be built or loaded.
#[derive(Debug, thiserror::Error)]
pub enum StubSceneError {
    #[error("cannot read stub scene {path}: {source}")]
    Read { path: String, source: std::io::Error },
    #[error("MuJoCo refused the stub scene {origin}: {message}")]
    Compile { origin: String, message: String },
    #[error("stub scene {origin} has no {kind} named '{name}' (the stub needs joint1..joint7 and act1..act7)")]
    Missing { origin: String, kind: &'static str, name: String },
    #[error("stub scene {origin}: {message}")]
    Invalid { origin: String, message: String },
    #[error("lab configuration for the stub scene: {0}")]
    Lab(String),
    #[error("target model for the stub scene: {0}")]
    Target(String),
}

/// The arm's measured joints and the simulated time they belong to, shared lock-free between the
/// plant (writer, after every `advance`/`reset`) and the camera (reader, at each exposure).
#[derive(Debug, Clone, Default)]
pub struct SharedArmState(Arc<AtomicCell<ArmSample>>);

/// One sample of [`SharedArmState`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmSample {
    /// Measured joint positions, radians.
    pub q: Joints,
    /// Simulated time of the sample, seconds.
    pub sim_time_s: f64,
}

impl SharedArmState {
    pub fn new(sample: ArmSample) -> Self {
        Self(Arc::new(AtomicCell::new(sample)))
    }
    pub fn load(&self) -> ArmSample {
        self.0.load()
    }
    pub fn store(&self, sample: ArmSample) {
        self.0.store(sample)
    }
}

/// The Sun's direction through a run, for the `orbit` scene: the direction the sunlight travels
/// (lab frame, unit) at playback ticks of the trajectory, and the loop tick at which playback
/// starts. Set once by the session (the schedule before the devices open, the start once the
/// approach is planned), read by the camera's render thread at each capture; lock-free, shared
/// by every clone.
#[derive(Debug, Clone, Default)]
pub struct SunTrack(Arc<SunTrackInner>);

#[derive(Debug)]
struct SunTrackInner {
    /// (playback tick, direction), ticks strictly ascending.
    points: OnceLock<Vec<(u64, [f64; 3])>>,
    /// The loop tick of playback tick 0; `u64::MAX` until known.
    start: AtomicU64,
}

impl Default for SunTrackInner {
    fn default() -> Self {
        Self { points: OnceLock::new(), start: AtomicU64::new(u64::MAX) }
    }
}

impl SunTrack {
    /// Set the schedule: (playback tick, direction the light travels) pairs. Points whose
    /// direction is not a finite non-zero vector, or whose tick does not follow the previous
    /// one, are dropped. Only the first call counts (the render thread may be reading it);
    /// `false` if a schedule was already set.
    pub fn set_schedule(&self, points: &[(u64, Vector3<f64>)]) -> bool {
        let mut kept: Vec<(u64, [f64; 3])> = Vec::with_capacity(points.len());
        for (tick, d) in points {
            let Some(u) = d.try_normalize(1e-12).filter(|u| u.iter().all(|x| x.is_finite())) else {
                continue;
            };
            if kept.last().is_some_and(|(t, _)| t >= tick) {
                continue;
            }
            kept.push((*tick, [u.x, u.y, u.z]));
        }
        self.0.points.set(kept).is_ok()
    }

    /// Playback tick 0 is loop tick `tick` (after the approach).
    pub fn set_playback_start(&self, tick: u64) {
        self.0.start.store(tick, Ordering::Release);
    }

    /// The Sun's direction at loop tick `tick`: interpolated (normalised lerp) between the
    /// schedule's points, held before the first and after the last; `None` without a schedule
    /// or before playback's start is known.
    pub fn direction_at(&self, tick: u64) -> Option<Vector3<f64>> {
        let points = self.0.points.get().filter(|p| !p.is_empty())?;
        let start = self.0.start.load(Ordering::Acquire);
        if start == u64::MAX {
            return None;
        }
        let i = tick.saturating_sub(start);
        let v = |k: usize| Vector3::from(points[k].1);
        let after = points.partition_point(|(t, _)| *t <= i);
        if after == 0 {
            return Some(v(0));
        }
        if after == points.len() {
            return Some(v(after - 1));
        }
        let (t0, t1) = (points[after - 1].0, points[after].0);
        let f = (i - t0) as f64 / (t1 - t0) as f64;
        let d = v(after - 1) * (1.0 - f) + v(after) * f;
        // Opposite neighbours (a half turn between two waypoints): hold the earlier one.
        Some(d.try_normalize(1e-9).unwrap_or_else(|| v(after - 1)))
    }
}

/// The compiled lab model and the ids the plant and the camera look things up by.
#[derive(Debug, Clone)]
pub struct LabModel {
    pub model: Arc<MjModel>,
    /// qpos address of joint1..joint7.
    pub qpos_adr: [usize; DOF],
    /// qvel address of joint1..joint7.
    pub dof_adr: [usize; DOF],
    /// Actuator id of act1..act7.
    pub actuator: [usize; DOF],
    /// Per body: does it belong to the arm (the tree that holds joint1)?
    pub arm_body: Vec<bool>,
    /// The target's body, if the scene has one (its geoms make the camera's mask).
    pub target_body: Option<usize>,
    /// The flange camera, if the scene has one.
    pub camera: Option<usize>,
    /// The OpenCV-axes camera site, if the scene has one.
    pub camera_site: Option<usize>,
    /// The Sun light, if the scene has one.
    pub sun: Option<usize>,
    /// How the scene is drawn (a user's MJCF counts as `lab`: its lights stay as written).
    pub scene_kind: SceneKind,
    /// The Sun's direction through the run (`orbit`).
    pub sun_track: SunTrack,
}

impl LabModel {
    /// The lab generated from `lab` with the primitive target, or the user's MJCF at `scene`.
    pub fn new(lab: &LabConfig, scene: Option<&Path>) -> Result<Self, StubSceneError> {
        match scene {
            Some(path) => {
                let text = std::fs::read_to_string(path).map_err(|source| {
                    StubSceneError::Read { path: path.display().to_string(), source }
                })?;
                Self::from_xml(&text, &path.display().to_string())
            }
            None => Self::generated(lab, &TargetModel::for_lab(lab)),
        }
    }

    /// The lab generated by [`mjcf::lab_mjcf`] (drawn as `lab.scene.kind` says).
    pub fn generated(lab: &LabConfig, target: &TargetModel) -> Result<Self, StubSceneError> {
        Self::generated_scene(lab, target, &SceneOptions::for_lab(lab))
    }

    /// The lab generated by [`mjcf::lab_scene_mjcf`], drawn as `options` say.
    pub fn generated_scene(
        lab: &LabConfig,
        target: &TargetModel,
        options: &SceneOptions,
    ) -> Result<Self, StubSceneError> {
        let xml = mjcf::lab_scene_mjcf(lab, target, options)?;
        let mut model = Self::from_xml(&xml, "<generated lab>")?;
        model.scene_kind = options.kind;
        Ok(model)
    }

    /// Compile MJCF text and check it has what the stub needs.
    pub fn from_xml(xml: &str, origin: &str) -> Result<Self, StubSceneError> {
        let model = MjModel::from_xml_string(xml).map_err(|e| StubSceneError::Compile {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        Self::from_model(Arc::new(model), origin)
    }

    fn from_model(model: Arc<MjModel>, origin: &str) -> Result<Self, StubSceneError> {
        let missing = |kind, name: &str| StubSceneError::Missing {
            origin: origin.to_string(),
            kind,
            name: name.to_string(),
        };
        let invalid =
            |message: String| StubSceneError::Invalid { origin: origin.to_string(), message };
        let mut qpos_adr = [0; DOF];
        let mut dof_adr = [0; DOF];
        let mut actuator = [0; DOF];
        let mut joint = [0; DOF];
        for j in 0..DOF {
            let jid = model
                .name_to_id(MjtObjBase::mjOBJ_JOINT, JOINT_NAMES[j])
                .ok_or_else(|| missing("joint", JOINT_NAMES[j]))?;
            if model.jnt_type()[jid] != mujoco_rs::prelude::MjtJoint::mjJNT_HINGE {
                return Err(invalid(format!("joint '{}' must be a hinge", JOINT_NAMES[j])));
            }
            joint[j] = jid;
            qpos_adr[j] = model.jnt_qposadr()[jid] as usize;
            dof_adr[j] = model.jnt_dofadr()[jid] as usize;
            let aid = model
                .name_to_id(MjtObjBase::mjOBJ_ACTUATOR, ACTUATOR_NAMES[j])
                .ok_or_else(|| missing("actuator", ACTUATOR_NAMES[j]))?;
            if model.actuator_trnid()[aid][0] as usize != jid {
                return Err(invalid(format!(
                    "actuator '{}' must drive joint '{}'",
                    ACTUATOR_NAMES[j], JOINT_NAMES[j]
                )));
            }
            actuator[j] = aid;
        }
        let root = model.body_rootid()[model.jnt_bodyid()[joint[0]] as usize];
        let arm_body: Vec<bool> =
            model.body_rootid().iter().enumerate().map(|(b, r)| b != 0 && *r == root).collect();
        let find = |kind, name: &str| model.name_to_id(kind, name);
        let target_body = find(MjtObjBase::mjOBJ_BODY, mjcf::TARGET_BODY);
        let camera = find(MjtObjBase::mjOBJ_CAMERA, CAMERA_NAME);
        let camera_site = find(MjtObjBase::mjOBJ_SITE, CAMERA_SITE);
        let sun = find(MjtObjBase::mjOBJ_LIGHT, mjcf::SUN_LIGHT);
        Ok(Self {
            model,
            qpos_adr,
            dof_adr,
            actuator,
            arm_body,
            target_body,
            camera,
            camera_site,
            sun,
            scene_kind: SceneKind::Lab,
            sun_track: SunTrack::default(),
        })
    }

    /// The name of geom `g`, or its body's name and index when it has none.
    pub fn geom_label(&self, g: usize) -> String {
        if let Some(n) = self.model.id_to_name(MjtObjBase::mjOBJ_GEOM, g).filter(|n| !n.is_empty())
        {
            return n.to_string();
        }
        let b = self.model.geom_bodyid()[g] as usize;
        let body = self.model.id_to_name(MjtObjBase::mjOBJ_BODY, b).unwrap_or("world");
        format!("{body}#geom{g}")
    }

    /// Joint limits of joint1..joint7 as compiled (radians).
    pub fn joint_limits(&self) -> [(f64, f64); DOF] {
        let mut out = [(f64::NEG_INFINITY, f64::INFINITY); DOF];
        for (j, o) in out.iter_mut().enumerate() {
            let jid = self.model.name_to_id(MjtObjBase::mjOBJ_JOINT, JOINT_NAMES[j]);
            if let Some(jid) = jid.filter(|id| self.model.jnt_limited()[*id]) {
                let r = self.model.jnt_range()[jid];
                *o = (r[0], r[1]);
            }
        }
        out
    }
}

/// Largest joint angle a command may carry, radians; anything beyond is garbage, not a pose.
pub const ABSURD_ANGLE_RAD: f64 = 100.0;

fn sane(q: &Joints) -> bool {
    q.iter().all(|v| v.is_finite() && v.abs() <= ABSURD_ANGLE_RAD)
}

/// The MuJoCo plant behind the stub's protocol server.
pub struct MujocoPlant {
    lab: LabModel,
    data: MjData<Arc<MjModel>>,
    /// Simulated time the server has asked for (the plant steps until it is within half a step).
    goal_time: f64,
    timestep: f64,
    limits: [(f64, f64); DOF],
    shared: SharedArmState,
    /// MuJoCo reset the state after a numerical instability (bad position/velocity/acceleration).
    diverged: bool,
}

impl std::fmt::Debug for MujocoPlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MujocoPlant")
            .field("time", &self.time())
            .field("q", &self.joints())
            .finish()
    }
}

impl MujocoPlant {
    /// The plant of the generated lab, or of the user's MJCF `scene` (which must have joints
    /// joint1..joint7 and position actuators act1..act7 driving them). The arm starts at rest at
    /// the all-zero pose.
    pub fn new(lab: &LabConfig, scene: Option<&Path>) -> Result<MujocoPlant, StubSceneError> {
        Ok(Self::from_lab_model(LabModel::new(lab, scene)?))
    }

    /// A plant on an already compiled model.
    pub fn from_lab_model(lab: LabModel) -> MujocoPlant {
        let data = MjData::new(lab.model.clone());
        let timestep = lab.model.opt().timestep;
        let limits = lab.joint_limits();
        let mut plant = MujocoPlant {
            lab,
            data,
            goal_time: 0.0,
            timestep,
            limits,
            shared: SharedArmState::default(),
            diverged: false,
        };
        plant.reset(&[0.0; DOF]);
        plant
    }

    /// The compiled model and its ids (for the camera: `SimCamera::new(plant.lab_model(), ...)`).
    pub fn lab_model(&self) -> LabModel {
        self.lab.clone()
    }

    /// The lock-free cell the plant publishes its measured joints to after every step.
    pub fn shared_state(&self) -> SharedArmState {
        self.shared.clone()
    }

    /// The simulation's fixed timestep, seconds.
    pub fn timestep(&self) -> f64 {
        self.timestep
    }

    /// Joint limits as compiled into the model (radians).
    pub fn joint_limits(&self) -> [(f64, f64); DOF] {
        self.limits
    }

    /// The first joint that sits on (within `tol` of) or beyond one of its limits, with its
    /// measured angle: what the box reports as a joint-limit error.
    pub fn joint_at_limit(&self, tol: f64) -> Option<(usize, f64)> {
        let q = self.joints();
        (0..DOF)
            .find(|&j| q[j] <= self.limits[j].0 + tol || q[j] >= self.limits[j].1 - tol)
            .map(|j| (j, q[j]))
    }

    /// True once MuJoCo has had to reset the simulation after a numerical instability (it puts
    /// the arm back at its model pose when positions, velocities or accelerations blow up). The
    /// server should treat it as an arm fault. Cleared by [`Plant::reset`].
    pub fn diverged(&self) -> bool {
        self.diverged
    }

    /// Every current contact between the arm and the scene (arm part first).
    pub fn collisions(&self) -> Vec<Collision> {
        self.contact_pairs().map(|(a, o)| self.named(a, o)).collect()
    }

    fn named(&self, arm: usize, other: usize) -> Collision {
        Collision { arm_part: self.lab.geom_label(arm), other: self.lab.geom_label(other) }
    }

    /// (arm geom, scene geom) of each contact that touches (distance <= 0).
    fn contact_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let bodies = self.lab.model.geom_bodyid();
        let is_arm = move |g: usize| self.lab.arm_body[bodies[g] as usize];
        self.data
            .contact()
            .iter()
            .filter(|c| c.dist <= 0.0 && c.geom[0] >= 0 && c.geom[1] >= 0)
            .filter_map(move |c| {
                let (g1, g2) = (c.geom[0] as usize, c.geom[1] as usize);
                match (is_arm(g1), is_arm(g2)) {
                    (true, false) => Some((g1, g2)),
                    (false, true) => Some((g2, g1)),
                    _ => None,
                }
            })
    }

    fn publish(&self) {
        self.shared.store(ArmSample { q: self.joints(), sim_time_s: self.time() });
    }
}

impl Plant for MujocoPlant {
    fn joints(&self) -> Joints {
        let qpos = self.data.qpos();
        std::array::from_fn(|j| qpos[self.lab.qpos_adr[j]])
    }

    fn velocities(&self) -> Joints {
        let qvel = self.data.qvel();
        std::array::from_fn(|j| qvel[self.lab.dof_adr[j]])
    }

    /// Sets the servo targets. A command with a NaN, infinite or absurd (beyond
    /// [`ABSURD_ANGLE_RAD`]) value is ignored (the box refuses it too); the previous targets stay.
    /// Targets beyond a joint limit are taken: the joint stops on its limit.
    fn command(&mut self, q: &Joints) {
        if !sane(q) {
            return;
        }
        let ctrl = self.data.ctrl_mut();
        for j in 0..DOF {
            ctrl[self.lab.actuator[j]] = q[j];
        }
    }

    fn reset(&mut self, q: &Joints) {
        let q = if sane(q) { *q } else { [0.0; DOF] };
        self.diverged = false;
        let goal = self.goal_time;
        self.data.reset();
        // Keep the clock running across resets: the server's time base must not jump back.
        self.data.set_time(goal);
        {
            let qpos = self.data.qpos_mut();
            for j in 0..DOF {
                qpos[self.lab.qpos_adr[j]] = q[j];
            }
        }
        self.command(&q);
        self.data.forward();
        self.publish();
    }

    fn advance(&mut self, dt: f64) {
        if !(dt > 0.0 && dt.is_finite()) {
            return;
        }
        self.goal_time += dt;
        while self.data.time() < self.goal_time - 0.5 * self.timestep {
            let before = self.data.time();
            self.data.step();
            if self.data.time() <= before {
                // MuJoCo reset the data (time back to 0): keep the server's clock, flag the fault.
                self.diverged = true;
                self.data.set_time(self.goal_time);
                break;
            }
        }
        self.publish();
    }

    fn time(&self) -> f64 {
        self.data.time()
    }

    fn collision(&self) -> Option<Collision> {
        self.contact_pairs().next().map(|(a, o)| self.named(a, o))
    }
}
