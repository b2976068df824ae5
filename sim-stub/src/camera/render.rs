//! The ray-casting renderer: one ray per pixel through MuJoCo (`mj_multiRay` from the camera's
//! optical centre), so it runs headless on a CPU-only machine.
//!
//! Per pixel (u, v) (OpenCV convention: integer coordinates are pixel centres) the ray is
//! `((u - cx) / fx, (v - cy) / fy, 1)` in OpenCV camera axes. Depth is the z-depth along the
//! optical axis (not the ray length), 0 where the ray hits nothing; the mask is 255 where the hit
//! geom belongs to the target body's tree; the colour is Lambert shading of the geom's albedo by
//! the Sun (`albedo * (ambient + level * max(0, n . l))`, normals from MuJoCo's ray-surface
//! intersection), with target pixels in shadow when a ray towards the Sun hits the target or the
//! arm first. No hit is black, as the paper's black background.

use crate::mujoco_plant::LabModel;
use hitl_hal::{Intrinsics, Joints, Pose, DOF};
use mujoco_rs::prelude::{MjData, MjModel};
use mujoco_rs::wrappers::mj_model::traits::ModelType;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::sync::Arc;

/// How the colour image is lit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// Ambient light as a fraction of full Sun on a surface facing it (dim: the enclosure is dark).
    pub ambient: f32,
    /// Cast shadow rays for target pixels (the target's self-shadowing and the arm's shadow).
    pub shadows: bool,
    /// Direction the Sun's light travels, lab frame; `None` uses the scene's `sun` light (from
    /// the lab's lamp towards the target), or straight down when the scene has none.
    pub sun_direction_lab: Option<Vector3<f64>>,
}

impl Default for Shading {
    fn default() -> Self {
        Self { ambient: 0.04, shadows: true, sun_direction_lab: None }
    }
}

/// One rendered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub intrinsics: Intrinsics,
    /// rgb8, row-major.
    pub color: Vec<u8>,
    /// z-depth, metres, 0 where nothing was hit.
    pub depth_m: Vec<f32>,
    /// mono8: 255 target, 0 else.
    pub mask: Vec<u8>,
}

/// Shadow rays see only the arm's (group 1) and the target's (group 2) geoms.
const SHADOW_GROUPS: [u8; 6] = [0, 1, 1, 0, 0, 0];

/// A renderer with its own `MjData` on the lab model.
pub struct Renderer {
    lab: LabModel,
    /// One `MjData` per ray-casting thread (the first is the renderer's own).
    data: Vec<MjData<Arc<MjModel>>>,
    /// The camera's own body: its geoms never block the view.
    camera_body: Option<usize>,
    albedo: Vec<[f32; 3]>,
    is_target: Vec<bool>,
    dirs: Vec<[f64; 3]>,
    normals: Vec<[f64; 3]>,
    pub shading: Shading,
}

impl Renderer {
    /// A renderer for `lab`; it needs the `camera_cv` site or the `flange_camera` camera.
    pub fn new(lab: LabModel) -> Result<Self, String> {
        let m = lab.model.clone();
        let camera_body = match (lab.camera_site, lab.camera) {
            (Some(s), _) => Some(m.site_bodyid()[s] as usize),
            (None, Some(c)) => Some(m.cam_bodyid()[c] as usize),
            (None, None) => {
                return Err(format!(
                    "the scene has neither a site '{}' nor a camera '{}' on the flange",
                    crate::mjcf::CAMERA_SITE,
                    crate::mjcf::CAMERA_NAME
                ))
            }
        };
        let target_root = lab.target_body.map(|b| m.body_rootid()[b]);
        let ngeom = m.geom_bodyid().len();
        let mut albedo = Vec::with_capacity(ngeom);
        let mut is_target = Vec::with_capacity(ngeom);
        for g in 0..ngeom {
            let mat = m.geom_matid()[g];
            let rgba = if mat >= 0 { m.mat_rgba()[mat as usize] } else { m.geom_rgba()[g] };
            albedo.push([rgba[0], rgba[1], rgba[2]]);
            let body = m.geom_bodyid()[g] as usize;
            is_target.push(target_root.is_some_and(|r| m.body_rootid()[body] == r));
        }
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, 8);
        let data = (0..threads).map(|_| MjData::new(m.clone())).collect();
        Ok(Self {
            lab,
            data,
            camera_body,
            albedo,
            is_target,
            dirs: Vec::new(),
            normals: Vec::new(),
            shading: Shading::default(),
        })
    }

    /// Cast rays on `threads` threads (1 to 64; default: the machine's cores, up to 8).
    pub fn set_threads(&mut self, threads: usize) {
        let q = self.joints();
        let threads = threads.clamp(1, 64);
        self.data.truncate(threads);
        while self.data.len() < threads {
            self.data.push(MjData::new(self.lab.model.clone()));
        }
        self.set_joints(&q);
    }

    /// Ray-casting threads in use.
    pub fn threads(&self) -> usize {
        self.data.len()
    }

    fn joints(&self) -> Joints {
        let qpos = self.data[0].qpos();
        std::array::from_fn(|j| qpos[self.lab.qpos_adr[j]])
    }

    /// Put the arm at `q` and compute the kinematics.
    pub fn set_joints(&mut self, q: &Joints) {
        for data in &mut self.data {
            {
                let qpos = data.qpos_mut();
                for j in 0..DOF {
                    qpos[self.lab.qpos_adr[j]] = q[j];
                }
            }
            data.forward_kinematics();
        }
    }

    /// Camera pose (OpenCV axes) in the lab frame for the current joints.
    pub fn camera_in_lab(&self) -> Pose {
        camera_in_lab(&self.lab, &self.data[0])
    }

    /// The arm base's pose in the lab frame.
    pub fn base_in_lab(&self) -> Pose {
        base_in_lab(&self.lab, &self.data[0])
    }

    /// Direction the Sun's light travels in the lab frame (unit).
    pub fn sun_direction(&self) -> Vector3<f64> {
        let d = match (self.shading.sun_direction_lab, self.lab.sun) {
            (Some(d), _) => d,
            (None, Some(l)) => Vector3::from(self.data[0].light_xdir()[l]),
            (None, None) => -Vector3::z(),
        };
        if d.norm() > 1e-12 && d.iter().all(|v| v.is_finite()) {
            d.normalize()
        } else {
            -Vector3::z()
        }
    }

    /// Render from `camera` (OpenCV axes, lab frame) with the current joints, principal point
    /// moved by `shift_px`, Sun at `level` (0..1).
    pub fn render_from(
        &mut self,
        camera: &Pose,
        intr: &Intrinsics,
        level: f32,
        shift_px: [f64; 2],
    ) -> Image {
        let (w, h) = (intr.width as usize, intr.height as usize);
        let n = w * h;
        let rot = camera.rotation.to_rotation_matrix();
        let (cx, cy) = (intr.cx + shift_px[0], intr.cy + shift_px[1]);
        self.dirs.clear();
        self.dirs.reserve(n);
        for v in 0..h {
            let y = (v as f64 - cy) / intr.fy;
            for u in 0..w {
                let x = (u as f64 - cx) / intr.fx;
                let d = rot * Vector3::new(x, y, 1.0).normalize();
                self.dirs.push([d.x, d.y, d.z]);
            }
        }
        self.normals.clear();
        self.normals.resize(n, [0.0; 3]);
        let origin = camera.translation.vector;
        let pass = Pass {
            origin: [origin.x, origin.y, origin.z],
            optical: rot * Vector3::z(),
            to_sun: -self.sun_direction(),
            level: level.clamp(0.0, 1.0),
            ambient: self.shading.ambient.max(0.0),
            shadows: self.shading.shadows,
            camera_body: self.camera_body,
            albedo: &self.albedo,
            is_target: &self.is_target,
        };
        let mut color = vec![0u8; 3 * n];
        let mut depth_m = vec![0.0f32; n];
        let mut mask = vec![0u8; n];
        // Contiguous chunks of pixels, one per thread, each with its own MjData.
        let chunk = n.div_ceil(self.data.len()).max(1);
        std::thread::scope(|scope| {
            let mut work = self
                .data
                .iter_mut()
                .zip(self.dirs.chunks(chunk))
                .zip(self.normals.chunks_mut(chunk))
                .zip(color.chunks_mut(3 * chunk))
                .zip(depth_m.chunks_mut(chunk))
                .zip(mask.chunks_mut(chunk))
                .map(|(((((data, dirs), normals), color), depth), mask)| {
                    (data, dirs, normals, color, depth, mask)
                });
            let first = work.next();
            for (data, dirs, normals, color, depth, mask) in work {
                let pass = &pass;
                scope.spawn(move || pass.cast(data, dirs, normals, color, depth, mask));
            }
            if let Some((data, dirs, normals, color, depth, mask)) = first {
                pass.cast(data, dirs, normals, color, depth, mask);
            }
        });
        Image { intrinsics: *intr, color, depth_m, mask }
    }
}

/// What every ray-casting thread of one frame shares.
struct Pass<'a> {
    origin: [f64; 3],
    optical: Vector3<f64>,
    to_sun: Vector3<f64>,
    level: f32,
    ambient: f32,
    shadows: bool,
    camera_body: Option<usize>,
    albedo: &'a [[f32; 3]],
    is_target: &'a [bool],
}

impl Pass<'_> {
    /// Cast the rays `dirs` and shade their pixels.
    fn cast(
        &self,
        data: &mut MjData<Arc<MjModel>>,
        dirs: &[[f64; 3]],
        normals: &mut [[f64; 3]],
        color: &mut [u8],
        depth_m: &mut [f32],
        mask: &mut [u8],
    ) {
        let (geoms, dist) =
            data.multi_ray(&self.origin, dirs, None, true, self.camera_body, 1.0e6, Some(normals));
        let origin = Vector3::from(self.origin);
        for i in 0..dirs.len() {
            let Some(g) = geoms[i] else { continue };
            let t = dist[i];
            if !(t >= 0.0 && t.is_finite()) {
                continue;
            }
            let d = Vector3::from(dirs[i]);
            depth_m[i] = (t * d.dot(&self.optical)) as f32;
            let target = self.is_target[g];
            if target {
                mask[i] = 255;
            }
            let mut nrm = Vector3::from(normals[i]);
            if nrm.dot(&d) > 0.0 {
                nrm = -nrm;
            }
            let mut lambert = nrm.dot(&self.to_sun).max(0.0);
            if lambert > 0.0 && target && self.shadows {
                let hit = Point3::from(origin + d * t + nrm * 1e-5);
                let to_sun = [self.to_sun.x, self.to_sun.y, self.to_sun.z];
                let (blocker, _) = data.ray(
                    &[hit.x, hit.y, hit.z],
                    &to_sun,
                    Some(&SHADOW_GROUPS),
                    true,
                    None,
                    None,
                );
                if blocker.is_some() {
                    lambert = 0.0;
                }
            }
            let shade = self.ambient + self.level * lambert as f32;
            for c in 0..3 {
                let v = (self.albedo[g][c] * shade * 255.0).round().clamp(0.0, 255.0);
                color[3 * i + c] = v as u8;
            }
        }
    }
}

fn pose(p: &[f64; 3], m: &[f64; 9]) -> Pose {
    let r = Rotation3::from_matrix_unchecked(Matrix3::new(
        m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8],
    ));
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

/// Camera pose (OpenCV axes) in the lab frame from `data`'s kinematics: the `camera_cv` site, or
/// the flange camera turned from MuJoCo's axes (looking down -z, y up).
pub fn camera_in_lab<M: ModelType>(lab: &LabModel, data: &MjData<M>) -> Pose {
    if let Some(s) = lab.camera_site {
        pose(&data.site_xpos()[s], &data.site_xmat()[s])
    } else if let Some(c) = lab.camera {
        let mj = pose(&data.cam_xpos()[c], &data.cam_xmat()[c]);
        mj * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    } else {
        Isometry3::identity()
    }
}

/// The arm base's pose in the lab frame from `data`'s kinematics.
pub fn base_in_lab<M: ModelType>(lab: &LabModel, data: &MjData<M>) -> Pose {
    let parents = lab.model.body_parentid();
    match (0..lab.arm_body.len()).find(|&b| lab.arm_body[b] && parents[b] == 0) {
        Some(b) => {
            let p = data.xpos()[b];
            let q = data.xquat()[b];
            Isometry3::from_parts(
                Translation3::new(p[0], p[1], p[2]),
                UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])),
            )
        }
        None => Isometry3::identity(),
    }
}
