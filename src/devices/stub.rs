//! The embedded MuJoCo stub of the arm, camera and light (SITL): started on loopback for a run
//! that names no `--arm`, with the faults to inject (`--stub-fault`), and the pieces of its scene
//! that the simulated camera and light share with it.

use super::{DeviceError, SimDepthModel, SimScene};
use hitl_hal::Joints;
use hitl_sim_stub::mjcf::TargetModel as StubTarget;
use hitl_sim_stub::mujoco_plant::{LabModel, MujocoPlant, SharedArmState};
use hitl_sim_stub::{Stub, StubConfig, StubHandle};
use hitl_trajectories::lab::LabConfig;
use std::net::SocketAddr;

/// A `--stub-fault KIND[:VALUE]@SECONDS`, parsed.
pub type StubFault = hitl_sim_stub::Fault;

/// The embedded stub: the arm server and its scene.
pub struct EmbeddedStub {
    handle: StubHandle,
    lab_model: LabModel,
    arm: SharedArmState,
    light: hitl_sim_stub::camera::LightLevel,
    camera_noise: hitl_sim_stub::camera::NoiseModel,
    /// The simulated camera's lens (the stub lab's `[camera] distortion`).
    camera_lens: hitl_hal::Distortion,
    render_backlog: hitl_sim_stub::camera::RenderBacklog,
}

/// Start the stub on loopback for `lab`, with `target` (in model units) shown at `scale`, the
/// scene drawn as `scene` says, and `faults` scheduled from its start; its arm powers up at
/// `initial_q` (`None`: the stub's own power-up pose).
///
/// `simulated`: the stub runs on the run's simulated clock (`--clock sim`): nothing in it keeps
/// time, the run advances it ([`EmbeddedStub::advance_to`]).
///
/// `fifo_priority` is the run loop's SCHED_FIFO priority, if it has one. A box has CPUs of its
/// own; the embedded stub shares the run's, so its threads (physics, command and report ports)
/// run just below the loop and its report reader (`fifo_priority - 2`): rendering, perception
/// and recording on the normal scheduler then cannot make the simulated arm lag its commands,
/// which the controller would rightly stop as a joint deviation.
#[allow(clippy::too_many_arguments)]
pub fn start_stub(
    faults: &[StubFault],
    lab: &LabConfig,
    target: &hitl_perception::TargetModel,
    scale: f64,
    scene: &hitl_sim_stub::mjcf::SceneOptions,
    fifo_priority: Option<i32>,
    initial_q: Option<hitl_hal::Joints>,
    simulated: bool,
) -> Result<EmbeddedStub, DeviceError> {
    let lab_model = LabModel::generated_scene(lab, &stub_target(target, scale), scene)
        .map_err(|e| DeviceError::Failed(format!("stub scene: {e}")))?;
    let plant = MujocoPlant::from_lab_model(lab_model.clone());
    let arm = plant.shared_state();
    let thread_start = match fifo_priority {
        Some(p) => hitl_sim_stub::ThreadStart::new(move || {
            // Refused (no privilege), the threads stay on the normal scheduler, as the loop's
            // own report already says real-time was refused.
            let _ = crate::rt::os::set_fifo_priority((p - 2).max(1));
        }),
        None => hitl_sim_stub::ThreadStart::default(),
    };
    let mut config =
        StubConfig { faults: faults.to_vec(), thread_start, simulated, ..StubConfig::ephemeral() };
    if let Some(q) = initial_q {
        config.initial_q = q;
    }
    let handle = Stub::start(config, Box::new(plant))
        .map_err(|e| DeviceError::Failed(format!("stub: {e}")))?;
    Ok(EmbeddedStub {
        handle,
        lab_model,
        arm,
        light: Default::default(),
        camera_noise: Default::default(),
        camera_lens: lab
            .camera
            .distortion
            .map_or(hitl_hal::Distortion::NONE, hitl_hal::Distortion::brown_conrady),
        render_backlog: Default::default(),
    })
}

/// The stub's view of `target` (in model units) shown at `scale`: the merged mesh that sets its
/// size, and its parts with their materials for the renderer.
pub fn stub_target(target: &hitl_perception::TargetModel, scale: f64) -> StubTarget {
    use hitl_perception::models::Texture;
    use hitl_sim_stub::mjcf::{TargetMaterial, TargetPart, TargetTexture};
    let f32s =
        |v: &[[f64; 3]]| -> Vec<[f32; 3]> { v.iter().map(|p| p.map(|x| x as f32)).collect() };
    let parts = target
        .parts
        .iter()
        .map(|p| TargetPart {
            name: p.name.clone(),
            vertices: f32s(&p.vertices),
            faces: p.faces.clone(),
            texcoords: p.texcoords.clone(),
            material: TargetMaterial {
                rgba: p.material.rgba,
                specular: p.material.specular,
                shininess: p.material.shininess,
                texture: p.material.texture.as_ref().map(|t| match t {
                    Texture::Png(path) => TargetTexture::Png(path.clone()),
                    Texture::CellGrid { cell_rgb, line_rgb } => {
                        TargetTexture::CellGrid { cell_rgb: *cell_rgb, line_rgb: *line_rgb }
                    }
                }),
            },
        })
        .collect();
    StubTarget {
        mesh: Some(target.vertices_faces()),
        greatest_dimension_m: target.greatest_dimension_m() * scale,
        parts,
    }
}

impl EmbeddedStub {
    /// The simulated camera's depth as `model` says (ideal: as rendered; orbbec: the Gemini 305's
    /// stereo depth, docs/sim-camera.md), its noise seeded with `seed`.
    pub fn with_depth_model(mut self, model: SimDepthModel, seed: u64) -> Self {
        use hitl_sim_stub::camera::{DepthModel, StereoDepth};
        self.camera_noise.depth_model = match model {
            SimDepthModel::Ideal => DepthModel::Ideal,
            SimDepthModel::Orbbec => DepthModel::Orbbec(StereoDepth::GEMINI_305),
        };
        self.camera_noise.seed = seed;
        self
    }

    /// The stub's command port.
    pub fn cmd_addr(&self) -> SocketAddr {
        self.handle.cmd_addr()
    }

    /// Where the stub serves the report stream `kind`, if it does.
    pub fn report_addr(&self, kind: super::arm::ReportKind) -> Option<SocketAddr> {
        self.handle.report_addr(kind)
    }

    /// The Sun's direction through the run, which the simulated camera reads (`orbit`).
    pub fn sun_track(&self) -> &hitl_sim_stub::mujoco_plant::SunTrack {
        &self.lab_model.sun_track
    }

    /// The scene the simulated camera, light and inputs share with the stub.
    pub fn scene(&self) -> SimScene<'_> {
        SimScene {
            lab_model: &self.lab_model,
            arm: &self.arm,
            light: &self.light,
            inputs: self.handle.inputs(),
            camera_noise: self.camera_noise,
            camera_lens: self.camera_lens,
            render_backlog: &self.render_backlog,
        }
    }

    /// On a simulated clock: step the stub to `t_ns` (physics, faults, reports due by then).
    pub fn advance_to(&self, t_ns: u64) {
        self.handle.advance_to(t_ns);
    }

    /// On a simulated clock, the stub's counters; `None` on the wall clock.
    pub fn sim(&self) -> Option<&hitl_sim_stub::server::sim_clock::SimState> {
        self.handle.sim()
    }

    /// Whether the stub's command port is stalled by a fault now.
    pub fn replies_stalled(&self) -> bool {
        self.handle.replies_stalled()
    }

    /// Whether every capture the simulated camera took has been rendered.
    pub fn renders_done(&self) -> bool {
        self.render_backlog.idle()
    }

    /// Captures the simulated camera has finished rendering (delivered or dropped).
    pub fn frames_rendered(&self) -> u64 {
        self.render_backlog.rendered()
    }

    /// Shut the stub down; where its arm ended.
    pub fn close(self) -> Joints {
        let q = self.handle.plant_joints();
        self.handle.shutdown();
        q
    }
}
