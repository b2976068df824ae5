//! The MuJoCo-renderer camera: MuJoCo's own OpenGL renderer on an offscreen EGL context (a GPU's
//! when there is one, Mesa's software device otherwise), lit by the scene's lights with its
//! materials, about 11x the ray cast's frames/s at 1280x1024 on a 2-core machine (53 against
//! 4.6 frames/s of colour + depth + mask, docs/stub-scene.md).
//!
//! One capture is two passes from the same camera: the whole scene (colour and depth), then the
//! target alone (depth only counts); a pixel is the target's (mask 255) where the target-only
//! depth is the scene's depth, i.e. the target is what the camera sees there. (MuJoCo's
//! segmentation flags live on the scene, which the renderer does not lend out mutably.)
//!
//! The renderer owns a copy of the lab model, changed only in what drawing reads: the flange
//! camera's intrinsics (focal lengths and principal point from the capture's [`Intrinsics`], the
//! OpenCV pinhole model), the offscreen buffer size, the drawing range (near 1 cm, far
//! [`FAR_M`] in `lab`, [`mjcf::ORBIT_DRAW_RANGE_M`] in `orbit` so the Earth is drawn; depth
//! beyond [`FAR_M`] is no return, 0, in both), the Sun's brightness (the light level), the
//! headlight (ambient only, as [`Shading::ambient`]), and geom groups: the camera's own body is
//! hidden ([`HIDDEN_GROUP`]), the target's tree is drawn in [`TARGET_GROUP`], collision-only
//! geoms ([`mjcf::COLLISION_ONLY_GROUP`]) are never drawn.
//!
//! Shadows: the Sun casts them (MuJoCo's shadow map, [`mjcf::SHADOW_MAP_SIZE`] texels; the
//! keep-out sphere around the lamp is collision only, so it no longer blinds the light's shadow
//! camera). In `orbit` the Sun is directional and its direction is set on the render thread's
//! data before each capture, from the run's [`SunTrack`] at the capture's tick (or
//! [`GlRenderer::set_sun_direction`]); its shadow camera is moved to the target's Sun side so
//! the shadow map stays centred on the target. The mask pass draws no shadows.
//!
//! The EGL context belongs to the thread that made it: build and use a [`GlRenderer`] on one
//! thread (the camera's render thread does).

use super::render::{self, Image, Shading};
use crate::mjcf;
use crate::mujoco_plant::{LabModel, SunTrack};
use hitl_hal::{Intrinsics, Joints, Pose, DOF};
use hitl_trajectories::lab::SceneKind;
use mujoco_rs::prelude::{MjData, MjModel};
use mujoco_rs::renderer::MjRenderer;
use mujoco_rs::wrappers::mj_visualization::{MjvCamera, MjvOption};
use nalgebra::{UnitQuaternion, Vector3};

/// Farthest depth the camera returns, metres (the Orbbec Gemini class reads to about 10 m).
pub const FAR_M: f64 = 10.0;
/// Nearest depth drawn, metres.
pub const NEAR_M: f64 = 0.01;
/// The geom group the target's geoms are drawn in.
pub const TARGET_GROUP: i32 = 4;
/// The geom group the camera's own body is moved to, never drawn.
pub const HIDDEN_GROUP: i32 = 5;

/// Why MuJoCo's renderer could not start: the EGL device or the scene.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GlError {
    /// No EGL device opened an offscreen context.
    #[error("MuJoCo's renderer has no usable EGL device: {0}")]
    NoEgl(String),
    #[error("MuJoCo's renderer: {0}")]
    Scene(String),
}

/// MuJoCo's OpenGL renderer on a copy of the lab model.
pub struct GlRenderer {
    lab: LabModel,
    data: MjData<Box<MjModel>>,
    /// A twin of `data`'s model: drawing parameters are changed on it, then the two are swapped
    /// (a data's model is changed by swapping in a compatible one, not in place).
    spare: Option<Box<MjModel>>,
    /// Built for `size`; rebuilt when a capture asks for another size.
    renderer: Option<(MjRenderer, (u32, u32))>,
    camera: usize,
    sun_diffuse: Option<[f32; 3]>,
    sun_specular: Option<[f32; 3]>,
    pub shading: Shading,
    target_depth: Vec<f32>,
    scene_kind: SceneKind,
    sun_track: SunTrack,
    /// The loop tick of the capture being drawn (for the Sun track).
    capture_tick: Option<u64>,
    /// A fixed Sun direction (tests, benchmarks): wins over the track.
    sun_override: Option<Vector3<f64>>,
    /// The directional Sun's direction as the scene was written.
    sun_default: Option<Vector3<f64>>,
    /// The Sun direction the last capture was drawn with (`orbit`).
    sun_used: Option<Vector3<f64>>,
    /// Do the scene's lights cast shadows in the model now (off for the mask pass)?
    shadows_on: bool,
    /// Lights that cast shadows as the scene was written.
    shadow_lights: Vec<usize>,
}

impl GlRenderer {
    /// A renderer for `lab` (it needs the flange camera). Opens the EGL context on the calling
    /// thread at once (at `width` x `height`), so a machine without a usable device is known
    /// before anything moves.
    pub fn new(lab: LabModel, width: u32, height: u32) -> Result<Self, GlError> {
        let Some(camera) = lab.camera else {
            return Err(GlError::Scene(format!(
                "the scene has no camera '{}' on the flange",
                crate::mjcf::CAMERA_NAME
            )));
        };
        let mut model = Box::new((*lab.model).clone());
        let m = &mut *model;
        let camera_body = match lab.camera_site {
            Some(s) => m.site_bodyid()[s] as usize,
            None => m.cam_bodyid()[camera] as usize,
        };
        let target_root = lab.target_body.map(|b| m.body_rootid()[b]);
        let ngeom = m.geom_bodyid().len();
        for g in 0..ngeom {
            let body = m.geom_bodyid()[g] as usize;
            if body == camera_body {
                m.geom_group_mut()[g] = HIDDEN_GROUP;
            } else if target_root.is_some_and(|r| m.body_rootid()[body] == r) {
                m.geom_group_mut()[g] = TARGET_GROUP;
            } else if m.geom_group()[g] >= TARGET_GROUP {
                m.geom_group_mut()[g] = 0;
            }
        }
        let extent = m.stat().extent.max(1e-6);
        let draw_range = match lab.scene_kind {
            SceneKind::Lab => FAR_M,
            SceneKind::Orbit => mjcf::ORBIT_DRAW_RANGE_M,
        };
        {
            let vis = m.vis_mut();
            vis.map.znear = (NEAR_M / extent) as f32;
            vis.map.zfar = (draw_range / extent) as f32;
            vis.headlight.diffuse = [0.0; 3];
            vis.headlight.specular = [0.0; 3];
            // One sample per pixel, at its centre, like the ray cast and a camera's pixel grid:
            // multisampling (MuJoCo's default 4) costs about half the frame in software.
            vis.quality.offsamples = 0;
        }
        let (sun_diffuse, sun_specular) = match lab.sun {
            Some(l) => (Some(m.light_diffuse()[l]), Some(m.light_specular()[l])),
            None => (None, None),
        };
        let sun_default = lab.sun.map(|l| Vector3::from(m.light_dir()[l]));
        let shadow_lights: Vec<usize> =
            (0..m.light_castshadow().len()).filter(|&l| m.light_castshadow()[l]).collect();
        let (scene_kind, sun_track) = (lab.scene_kind, lab.sun_track.clone());
        let spare = Some(model.clone());
        let data = MjData::new(model);
        let mut r = Self {
            lab,
            data,
            spare,
            renderer: None,
            camera,
            sun_diffuse,
            sun_specular,
            shading: Shading::default(),
            target_depth: Vec::new(),
            scene_kind,
            sun_track,
            capture_tick: None,
            sun_override: None,
            sun_default,
            sun_used: None,
            shadows_on: true,
            shadow_lights,
        };
        r.set_joints(&[0.0; DOF]);
        r.ensure_size(width.max(1), height.max(1))?;
        Ok(r)
    }

    /// Build the renderer for `width` x `height` unless it already is.
    fn ensure_size(&mut self, width: u32, height: u32) -> Result<(), GlError> {
        if self.renderer.as_ref().is_some_and(|(_, s)| *s == (width, height)) {
            return Ok(());
        }
        self.renderer = None; // frees the old context before making the new one
        self.update_model(|m| {
            let g = &mut m.vis_mut().global;
            g.offwidth = width as i32;
            g.offheight = height as i32;
        })?;
        let renderer = MjRenderer::builder()
            .width(width)
            .height(height)
            .rgb(true)
            .depth(true)
            .camera(MjvCamera::new_fixed(self.camera))
            .build(self.data.model())
            .map_err(|e| match e {
                mujoco_rs::renderer::RendererError::GlutinError(g) => {
                    GlError::NoEgl(format!("{g} ({})", missing_packages()))
                }
                other => GlError::Scene(other.to_string()),
            })?;
        self.renderer = Some((renderer, (width, height)));
        Ok(())
    }

    /// Change drawing parameters of the model (`f` runs on both twins, so they stay equal).
    fn update_model(&mut self, f: impl Fn(&mut MjModel)) -> Result<(), GlError> {
        let mut next = self.spare.take().ok_or_else(|| GlError::Scene("model lost".into()))?;
        f(&mut next);
        let mut old = self.data.try_swap_model(next).map_err(|e| GlError::Scene(e.to_string()))?;
        f(&mut old);
        self.spare = Some(old);
        Ok(())
    }

    /// The loop tick of the next capture: in `orbit` the Sun's direction is the run's
    /// [`SunTrack`] at this tick.
    pub fn set_capture_tick(&mut self, tick: u64) {
        self.capture_tick = Some(tick);
    }

    /// Draw the `orbit` Sun travelling along `dir` (lab frame) from now on, whatever the track
    /// says; `None` gives the track back.
    pub fn set_sun_direction(&mut self, dir: Option<Vector3<f64>>) {
        self.sun_override = dir.and_then(|d| d.try_normalize(1e-12));
    }

    /// The direction (lab frame, unit) the last `orbit` capture's sunlight travelled.
    pub fn sun_direction(&self) -> Option<Vector3<f64>> {
        self.sun_used
    }

    /// Turn the scene's shadows on or off (the mask pass needs none).
    fn set_shadows(&mut self, on: bool) -> Result<(), GlError> {
        if self.shadows_on == on || self.shadow_lights.is_empty() {
            return Ok(());
        }
        let lights = std::mem::take(&mut self.shadow_lights);
        let r = self.update_model(|m| {
            for &l in &lights {
                m.light_castshadow_mut()[l] = on;
            }
        });
        self.shadow_lights = lights;
        self.shadows_on = on;
        r
    }

    /// Put the arm at `q` and compute the kinematics.
    pub fn set_joints(&mut self, q: &Joints) {
        {
            let qpos = self.data.qpos_mut();
            for j in 0..DOF {
                qpos[self.lab.qpos_adr[j]] = q[j];
            }
        }
        self.data.forward_kinematics();
    }

    /// Camera pose (OpenCV axes) in the lab frame for the current joints.
    pub fn camera_in_lab(&self) -> Pose {
        render::camera_in_lab(&self.lab, &self.data)
    }

    /// The arm base's pose in the lab frame.
    pub fn base_in_lab(&self) -> Pose {
        render::base_in_lab(&self.lab, &self.data)
    }

    /// Render from `camera` (OpenCV axes, lab frame) with the current joints, principal point
    /// moved by `shift_px`, Sun at `level` (0..1). A failure of the GL context after it opened
    /// gives `Err` (the camera reports it as a lost device).
    pub fn render_from(
        &mut self,
        camera: &Pose,
        intr: &Intrinsics,
        level: f32,
        shift_px: [f64; 2],
    ) -> Result<Image, GlError> {
        self.ensure_size(intr.width, intr.height)?;
        let (w, h) = (intr.width as usize, intr.height as usize);
        let n = w * h;
        self.set_shadows(true)?;
        self.place_camera(camera, intr, level, shift_px)?;
        self.place_sun();
        let cam = self.camera;
        let Some((renderer, _)) = self.renderer.as_mut() else {
            return Err(GlError::Scene("renderer not built".into()));
        };
        let err = |e: mujoco_rs::renderer::RendererError| GlError::Scene(e.to_string());
        // The whole scene (the camera's own body and collision-only geoms hidden).
        // (Sites are markers, not surfaces: none drawn.)
        let mut opts =
            MjvOption { geomgroup: [1, 1, 1, 0, 1, 0], sitegroup: [0; 6], ..Default::default() };
        renderer.set_opts(opts.clone());
        if !renderer.rgb_enabled() {
            renderer.set_rgb_rendering(true);
        }
        renderer.set_camera(MjvCamera::new_fixed(cam));
        renderer.sync_data(&mut self.data).map_err(err)?;
        renderer.render().map_err(err)?;
        let color = renderer.rgb_flat().map(<[u8]>::to_vec).unwrap_or_else(|| vec![0; 3 * n]);
        let far = (FAR_M * (1.0 - 1e-4)) as f32;
        let mut depth_m: Vec<f32> = match renderer.depth_flat() {
            Some(d) => d.iter().map(|&z| if z.is_finite() && z < far { z } else { 0.0 }).collect(),
            None => vec![0.0; n],
        };
        depth_m.resize(n, 0.0);
        // The target alone: where its depth is the scene's, the camera sees the target.
        // (Depth only: not reading the colour back saves a fifth of the frame's time; no
        // shadow pass either.)
        self.set_shadows(false)?;
        let Some((renderer, _)) = self.renderer.as_mut() else {
            return Err(GlError::Scene("renderer not built".into()));
        };
        opts.geomgroup = [0, 0, 0, 0, 1, 0];
        renderer.set_opts(opts);
        renderer.set_rgb_rendering(false);
        renderer.sync_data(&mut self.data).map_err(err)?;
        renderer.render().map_err(err)?;
        self.target_depth.clear();
        if let Some(d) = renderer.depth_flat() {
            self.target_depth.extend_from_slice(d);
        }
        self.target_depth.resize(n, f32::INFINITY);
        let mask = depth_m
            .iter()
            .zip(&self.target_depth)
            .map(|(&z, &t)| if z > 0.0 && (t - z).abs() <= 1e-4 + 1e-4 * z { 255 } else { 0 })
            .collect();
        Ok(Image { intrinsics: *intr, color, depth_m, mask })
    }

    /// In `orbit`, point the Sun for this capture (fixed direction, else the track at the
    /// capture's tick, else the scene's) and put its shadow camera on the target's Sun side.
    /// Written on the data after the kinematics, as the camera's pose is.
    fn place_sun(&mut self) {
        let Some(l) = self.lab.sun.filter(|_| self.scene_kind == SceneKind::Orbit) else {
            return;
        };
        let track = self.capture_tick.and_then(|t| self.sun_track.direction_at(t));
        let Some(dir) = self.sun_override.or(track).or(self.sun_default) else { return };
        let centre = match self.lab.target_body {
            Some(b) => Vector3::from(self.data.xpos()[b]),
            None => Vector3::from(self.data.light_xpos()[l]) + dir * mjcf::SUN_SHADOW_DISTANCE_M,
        };
        let pos = centre - dir * mjcf::SUN_SHADOW_DISTANCE_M;
        self.data.light_xdir_mut()[l] = [dir.x, dir.y, dir.z];
        self.data.light_xpos_mut()[l] = [pos.x, pos.y, pos.z];
        self.sun_used = Some(dir);
    }

    /// Set the flange camera to `camera` with `intr`'s projection, and the Sun to `level`.
    fn place_camera(
        &mut self,
        camera: &Pose,
        intr: &Intrinsics,
        level: f32,
        shift: [f64; 2],
    ) -> Result<(), GlError> {
        let c = self.camera;
        let level = level.clamp(0.0, 1.0);
        let ambient = self.shading.ambient.max(0.0);
        let (sun, sun_diffuse, sun_specular) = (self.lab.sun, self.sun_diffuse, self.sun_specular);
        self.update_model(|m| {
            // MuJoCo's intrinsics are lengths on a sensor of sensorsize: pixels as the unit, the
            // principal point as an offset from the sensor's centre, x left and y up (found by
            // rendering against the ray cast, which then agree pixel for pixel on the target's
            // mask: tests/camera_gl.rs). OpenCV's centre of a W-pixel row is (W - 1) / 2
            // (integer coordinates are pixel centres).
            m.cam_sensorsize_mut()[c] = [intr.width as f32, intr.height as f32];
            let (cx, cy) = (intr.cx + shift[0], intr.cy + shift[1]);
            let px = (f64::from(intr.width) - 1.0) / 2.0 - cx;
            let py = (f64::from(intr.height) - 1.0) / 2.0 - cy;
            m.cam_intrinsic_mut()[c] = [intr.fx as f32, intr.fy as f32, px as f32, py as f32];
            m.cam_fovy_mut()[c] =
                (2.0 * (f64::from(intr.height) / (2.0 * intr.fy)).atan()).to_degrees();
            if let (Some(l), Some(d), Some(s)) = (sun, sun_diffuse, sun_specular) {
                m.light_diffuse_mut()[l] = d.map(|v| v * level);
                m.light_specular_mut()[l] = s.map(|v| v * level);
            }
            m.vis_mut().headlight.ambient = [ambient; 3];
        })?;
        // MuJoCo's camera looks down its -z with y up: the OpenCV axes turned half a turn about x.
        let mj = camera * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let r = mj.rotation.to_rotation_matrix();
        let t = mj.translation.vector;
        self.data.cam_xpos_mut()[c] = [t.x, t.y, t.z];
        let mut xmat = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                xmat[3 * i + j] = r[(i, j)];
            }
        }
        self.data.cam_xmat_mut()[c] = xmat;
        Ok(())
    }
}

/// The Debian packages whose files MuJoCo's offscreen rendering needs and this machine lacks, as
/// a sentence for the error.
pub fn missing_packages() -> String {
    let dirs =
        ["/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib"];
    let has = |path: &str| {
        if path.starts_with('/') {
            std::path::Path::new(path).exists()
        } else {
            dirs.iter().any(|d| std::path::Path::new(d).join(path).exists())
        }
    };
    let env: Vec<String> =
        ["__EGL_VENDOR_LIBRARY_FILENAMES", "__EGL_VENDOR_LIBRARY_DIRS", "EGL_PLATFORM"]
            .iter()
            .filter_map(|k| std::env::var(k).ok().map(|v| format!("{k}={v}")))
            .collect();
    diagnose(has, &env)
}

/// What to tell the user, given which files exist (`has`: a library path relative to the
/// library directories, or an absolute path) and the EGL variables set (`env`, `NAME=value`).
fn diagnose(has: impl Fn(&str) -> bool, env: &[String]) -> String {
    let mut missing = Vec::new();
    if !has("libEGL.so.1") {
        missing.push("libegl1");
    }
    if !has("libEGL_mesa.so.0") || !has("/usr/share/glvnd/egl_vendor.d/50_mesa.json") {
        missing.push("libegl-mesa0");
    }
    if !has("dri/swrast_dri.so") && !has("dri/kms_swrast_dri.so") {
        missing.push("libgl1-mesa-dri");
    }
    if !missing.is_empty() {
        format!(
            "missing Debian package(s) {}: run 'sudo apt-get install {}' (scripts/setup.sh does)",
            missing.join(", "),
            missing.join(" ")
        )
    } else if env.is_empty() {
        "libegl1, libegl-mesa0 and libgl1-mesa-dri are installed, yet no EGL device opened a \
         context (a GPU driver's EGL vendor file may be broken)"
            .into()
    } else {
        format!(
            "libegl1, libegl-mesa0 and libgl1-mesa-dri are installed, but the environment points \
             EGL elsewhere: {}",
            env.join(" ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::diagnose;

    #[test]
    fn the_missing_package_is_named() {
        let all = |_: &str| true;
        let no_mesa_egl = |p: &str| !p.contains("mesa");
        let no_dri = |p: &str| !p.starts_with("dri/");
        let nothing = |_: &str| false;
        let m = diagnose(no_mesa_egl, &[]);
        assert!(
            m.contains("package(s) libegl-mesa0:") && m.contains("apt-get install libegl-mesa0"),
            "{m}"
        );
        let m = diagnose(no_dri, &[]);
        assert!(m.contains("package(s) libgl1-mesa-dri:"), "{m}");
        let m = diagnose(nothing, &[]);
        assert!(m.contains("libegl1, libegl-mesa0, libgl1-mesa-dri:"), "{m}");
        let m = diagnose(all, &["EGL_PLATFORM=x".into()]);
        assert!(m.contains("installed") && m.contains("EGL_PLATFORM=x"), "{m}");
        assert!(!diagnose(all, &[]).contains("missing"));
    }
}
