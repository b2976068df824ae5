//! The lab scene as MJCF, written by the project from its own data: the xArm7 from
//! [`kinematics::CHAIN`], the enclosure from [`LabConfig`], the tripod, the target spacecraft, the
//! flange camera and the Sun.
//!
//! Frames: MuJoCo's world frame is the **lab frame** (origin at a floor corner of the enclosure,
//! z up); the arm's `base` body sits at [`LabConfig::base_in_lab`]. Every geom that belongs to the
//! arm (including the flange and the camera body) collides only with scene geoms (enclosure,
//! tripod, target, light), never with another arm geom: arm geoms have `contype=1 conaffinity=0`,
//! scene geoms `contype=0 conaffinity=1`. The arm's capsules are the ones of
//! [`kinematics::arm_capsules`], so the stub's collisions agree with the preflight.
//!
//! Servo model (see docs/stub-scene.md): each joint has a position actuator (`kp`, `kv` chosen
//! for a natural frequency of [`SERVO_OMEGA`] rad/s, critically damped, on a nominal inertia that
//! includes the joint's armature), so the arm tracks a 250 Hz servo stream with about
//! `2 / SERVO_OMEGA` seconds of lag. Gravity is on and compensated by the drives (`gravcomp="1"`
//! on every arm body), as the box's own gravity compensation does.
//!
//! Looks (docs/stub-scene.md): two scene kinds ([`SceneKind`]) share every collision geom, so the
//! stub's physics and the preflight agree whichever is drawn. Geom group
//! [`COLLISION_ONLY_GROUP`] is never drawn (keep-out volumes; in `orbit` also the enclosure, the
//! tripod and the arm); visual-only geoms (lamp housing, Earth) collide with nothing. `lab` is
//! the enclosure's twin lit by the studio light as a spot light; `orbit` is a black sky with the
//! Earth along the Hill frame's nadir and a directional Sun whose direction the camera sets at
//! each capture. Both cast shadows.

use crate::mujoco_plant::StubSceneError;
use crate::target_look::{write_assets, write_target};
pub use crate::target_look::{
    TargetMaterial, TargetModel, TargetPart, TargetTexture, TriangleMesh,
};
use hitl_hal::Pose;
use hitl_trajectories::kinematics::{self, CHAIN, DOF, LINK_RADII};
use hitl_trajectories::lab::{LabConfig, SceneKind};
use hitl_trajectories::planner::mapping;
use nalgebra::{Matrix3, Point3, UnitQuaternion, Vector3};
use std::fmt::Write as _;

/// Joint names, joint 1 first. A user scene must use these names.
pub const JOINT_NAMES: [&str; DOF] =
    ["joint1", "joint2", "joint3", "joint4", "joint5", "joint6", "joint7"];
/// Position actuator names, one per joint, same order. A user scene must use these names.
pub const ACTUATOR_NAMES: [&str; DOF] = ["act1", "act2", "act3", "act4", "act5", "act6", "act7"];
/// The arm's fixed base body (child of the world).
pub const BASE_BODY: &str = "base";
/// Link bodies 1-7 (link7 is the flange), same order as [`kinematics::link_frames`]` [1..]`.
pub const LINK_BODIES: [&str; DOF] =
    ["link1", "link2", "link3", "link4", "link5", "link6", "link7"];
/// The target spacecraft's body: every geom of this body counts as target in the camera's mask.
pub const TARGET_BODY: &str = "target";
/// The flange camera (MuJoCo axes: looks down its -z, y up).
pub const CAMERA_NAME: &str = "flange_camera";
/// A site at the camera's optical centre with OpenCV axes (x right, y down, z forward).
pub const CAMERA_SITE: &str = "camera_cv";
/// The light that plays the Sun: the studio light (a spot) in `lab`, a directional light in
/// `orbit`.
pub const SUN_LIGHT: &str = "sun";
/// The geom group that collides but is never drawn.
pub const COLLISION_ONLY_GROUP: i32 = 3;
/// The Earth's geom in `orbit` (visual only).
pub const EARTH_GEOM: &str = "earth";
/// The studio lamp's housing in `lab` (visual only, behind the light, out of its beam).
pub const LAMP_GEOM: &str = "lamp-housing";
/// Angular radius of the Earth seen from the chief, degrees: the planner's default 12-hour orbit
/// (a = 26 560 km, Earth radius 6 378 km gives asin(6378 / 26560) = 13.9 deg).
pub const EARTH_ANGULAR_RADIUS_DEG: f64 = 13.9;
/// Distance from the target to the Earth's centre in the scene, metres: beyond the camera's
/// depth range (the depth image never sees it), inside the drawing range.
pub const EARTH_DISTANCE_M: f64 = 60.0;
/// Farthest distance drawn in `orbit`, metres (the Earth's far side fits).
pub const ORBIT_DRAW_RANGE_M: f64 = 100.0;
/// Half the side of the directional Sun's shadow map square, at least, metres (around the
/// target; [`shadow_half_size_m`]).
pub const SUN_SHADOW_HALF_M: f64 = 0.05;
/// The studio light's beam: cutoff (half angle, degrees) and exponent (falloff inside it).
pub const SPOT_CUTOFF_DEG: f64 = 25.0;
pub const SPOT_EXPONENT: f64 = 8.0;
/// Shadow map side, texels. MuJoCo's default is 4096; a software renderer fills the map at every
/// frame, and 1024 costs a quarter of 2048 (docs/stub-scene.md has the figures) while still giving
/// about 0.5 mm texels at the target in `lab` and 0.2 mm on the default target in `orbit`.
pub const SHADOW_MAP_SIZE: u32 = 1024;
/// The part of the studio light's beam its shadow map covers (MuJoCo's `shadowscale`): half the
/// cutoff each side of the axis, 12.5 deg, about 0.24 m around the target.
pub const SPOT_SHADOW_SCALE: f64 = 0.5;

/// Simulation timestep, seconds.
pub const TIMESTEP_S: f64 = 0.002;
/// Closed-loop natural frequency of every joint servo at its nominal inertia, rad/s.
pub const SERVO_OMEGA: f64 = 120.0;
/// Reflected rotor inertia (armature) per joint, kg m^2: harmonic drives of ratio ~100.
pub const ARMATURE: [f64; DOF] = [0.3, 0.3, 0.2, 0.2, 0.1, 0.1, 0.1];
/// Nominal joint-space inertia per joint (armature plus a typical link load), kg m^2, on which
/// the servo gains are tuned.
pub const NOMINAL_INERTIA: [f64; DOF] = [1.2, 1.2, 0.5, 0.5, 0.15, 0.12, 0.1];
/// Torque limit per joint, N m (assumed: xArm7-class drives).
pub const TORQUE_LIMIT: [f64; DOF] = [50.0, 50.0, 32.0, 32.0, 32.0, 20.0, 20.0];
/// Viscous joint damping, N m s/rad.
pub const JOINT_DAMPING: f64 = 0.1;
/// Link masses, kg (approximate xArm7; the camera is counted in link7).
const LINK_MASS: [f64; DOF] = [2.4, 1.9, 1.7, 1.4, 1.6, 1.2, 0.7];
/// Thickness of the enclosure's wall boxes, metres (outside the inner box).
const WALL_THICKNESS: f64 = 0.05;

/// Position gain of joint `j`'s servo, N m/rad.
pub fn servo_kp(j: usize) -> f64 {
    SERVO_OMEGA * SERVO_OMEGA * NOMINAL_INERTIA[j]
}

/// Velocity gain of joint `j`'s servo (critically damped at the nominal inertia), N m s/rad.
pub fn servo_kv(j: usize) -> f64 {
    2.0 * SERVO_OMEGA * NOMINAL_INERTIA[j]
}

/// Writes `v` as space-separated numbers (shortest representation that reads back exactly).
fn nums(v: &[f64]) -> String {
    let mut s = String::new();
    for (i, x) in v.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{x:e}");
    }
    s
}

fn pos_attr(p: &Vector3<f64>) -> String {
    nums(&[p.x, p.y, p.z])
}

/// MuJoCo quaternion order: w x y z.
fn quat_attr(q: &UnitQuaternion<f64>) -> String {
    nums(&[q.w, q.i, q.j, q.k])
}

fn frame_attrs(pose: &Pose) -> String {
    format!("pos=\"{}\" quat=\"{}\"", pos_attr(&pose.translation.vector), quat_attr(&pose.rotation))
}

/// One arm capsule: the body it is on (0 base, 1-7 links), its name, its segment in the body's
/// frame and its radius.
type ArmGeom = (usize, &'static str, Point3<f64>, Point3<f64>, f64);

/// The arm's capsule geoms. Mirrors [`kinematics::arm_capsules`].
fn arm_geoms(lab: &LabConfig) -> Vec<ArmGeom> {
    let names = kinematics::CAPSULE_NAMES;
    let o = |i: usize| Point3::from(Vector3::from(CHAIN[i].0));
    let zero = Point3::origin();
    let mount = lab.camera_mount();
    let cam = &lab.camera.body;
    vec![
        (0, names[0], zero, o(0), LINK_RADII[0]),
        // Capsule k runs from link k's origin to link k+1's origin, i.e. to CHAIN[k] in link k.
        (2, names[1], zero, o(2), LINK_RADII[1]),
        (3, names[2], zero, o(3), LINK_RADII[2]),
        (4, names[3], zero, o(4), LINK_RADII[3]),
        (5, names[4], zero, o(5), LINK_RADII[4]),
        (6, names[5], zero, o(6), LINK_RADII[5]),
        (7, names[6], zero, Point3::new(0.0, 0.0, 0.02), 0.04),
        (
            7,
            names[7],
            mount * Point3::new(-cam.half_width_m, 0.0, -cam.depth_m),
            mount * Point3::new(cam.half_width_m, 0.0, -cam.depth_m),
            cam.radius_m,
        ),
    ]
}

fn capsule_geom(
    out: &mut String,
    indent: &str,
    name: &str,
    a: &Point3<f64>,
    b: &Point3<f64>,
    r: f64,
) {
    let class = "arm";
    if (b - a).norm() < 1e-9 {
        let _ = writeln!(
            out,
            "{indent}<geom name=\"{name}\" class=\"{class}\" type=\"sphere\" size=\"{}\" pos=\"{}\"/>",
            nums(&[r]),
            pos_attr(&a.coords)
        );
    } else {
        let _ = writeln!(
            out,
            "{indent}<geom name=\"{name}\" class=\"{class}\" type=\"capsule\" size=\"{}\" fromto=\"{}\"/>",
            nums(&[r]),
            nums(&[a.x, a.y, a.z, b.x, b.y, b.z])
        );
    }
}

/// Inertial of body `i` (1-7): mass at the middle of its link segment, isotropic inertia of a
/// rod of its length and radius.
fn inertial(i: usize) -> String {
    let m = LINK_MASS[i - 1];
    let end = if i < DOF { Vector3::from(CHAIN[i].0) } else { Vector3::new(0.0, 0.0, 0.04) };
    let len = end.norm().max(0.05);
    let r = LINK_RADII[(i - 1).min(LINK_RADII.len() - 1)];
    let inertia = (m * (3.0 * r * r + len * len) / 12.0).max(m * r * r / 2.0);
    format!(
        "<inertial pos=\"{}\" mass=\"{}\" diaginertia=\"{}\"/>",
        pos_attr(&(end * 0.5)),
        nums(&[m]),
        nums(&[inertia, inertia, inertia])
    )
}

/// The default Sun direction in the lab frame: from the lab light towards the target.
pub fn sun_direction_lab(lab: &LabConfig) -> Vector3<f64> {
    let target = lab.base_in_lab() * lab.target_position_base();
    let light = Point3::from(Vector3::from(lab.light.position_lab_m));
    let d = target - light;
    if d.norm() > 1e-9 {
        d.normalize()
    } else {
        -Vector3::z()
    }
}

/// The MuJoCo camera's orientation in its body from an OpenCV-axes mount: MuJoCo looks down -z
/// with y up, OpenCV looks down +z with y down, so the two differ by a half turn about x.
pub fn mujoco_camera_from_opencv(opencv: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    opencv * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
}

/// What the scene shows besides the lab's geometry: its kind, and where the Hill frame of the
/// trajectory points (for the Earth in `orbit`).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneOptions {
    pub kind: SceneKind,
    /// RTN-to-base rotation of the trajectory's plan (`v_base = M v_rtn`, the NPZ's
    /// `meta.rtn_to_base`); the planner's default when the trajectory has none.
    pub rtn_to_base: Matrix3<f64>,
}

impl SceneOptions {
    /// `lab.scene.kind` with the planner's default Hill frame.
    pub fn for_lab(lab: &LabConfig) -> Self {
        Self { kind: lab.scene.kind, rtn_to_base: mapping::default_rtn_to_base() }
    }
}

/// The nadir (towards the Earth's centre, -R of the Hill frame) in the lab frame.
pub fn nadir_lab(lab: &LabConfig, rtn_to_base: &Matrix3<f64>) -> Vector3<f64> {
    let radial_base = rtn_to_base.column(0).into_owned();
    let n = -(lab.base_in_lab().rotation * radial_base);
    n.try_normalize(1e-12).unwrap_or_else(|| -Vector3::z())
}

/// The target's centre in the lab frame.
pub fn target_centre_lab(lab: &LabConfig) -> Point3<f64> {
    lab.base_in_lab() * lab.target_position_base()
}

/// Half the side of the directional Sun's shadow square for a target of greatest dimension
/// `size_m`, metres: the target's greatest dimension (a target centred on its frame reaches at
/// most sqrt(3)/2 of it from its centre; in `orbit` nothing else casts a shadow), at least
/// [`SUN_SHADOW_HALF_M`].
pub fn shadow_half_size_m(size_m: f64) -> f64 {
    SUN_SHADOW_HALF_M.max(size_m)
}

/// The scene's length scale (MuJoCo's `statistic/extent`), metres: half the enclosure's
/// diagonal. Fixed here so that the Earth's size does not change clip planes and shadow maps.
pub fn scene_extent_m(lab: &LabConfig) -> f64 {
    Vector3::from(lab.enclosure.size_m).norm() / 2.0
}

/// The whole lab as an MJCF document, in the scene kind `lab.scene.kind` names.
pub fn lab_mjcf(lab: &LabConfig, target: &TargetModel) -> Result<String, StubSceneError> {
    lab_scene_mjcf(lab, target, &SceneOptions::for_lab(lab))
}

/// The whole lab as an MJCF document, drawn as `options` say.
pub fn lab_scene_mjcf(
    lab: &LabConfig,
    target: &TargetModel,
    options: &SceneOptions,
) -> Result<String, StubSceneError> {
    lab.validate().map_err(|e| StubSceneError::Lab(e.to_string()))?;
    target.validate()?;
    if options.rtn_to_base.iter().any(|x| !x.is_finite()) {
        return Err(StubSceneError::Lab("the trajectory's rtn_to_base is not finite".into()));
    }
    let kind = options.kind;
    let mut x = String::with_capacity(16 * 1024);
    let _ = writeln!(x, "<mujoco model=\"hitl-lab\">");
    let _ = writeln!(x, "  <compiler angle=\"radian\" autolimits=\"true\"/>");
    let _ = writeln!(
        x,
        "  <option timestep=\"{}\" gravity=\"0 0 -9.81\" integrator=\"implicitfast\"/>",
        nums(&[TIMESTEP_S])
    );
    write_visual(&mut x, lab, target);
    write_defaults(&mut x, kind);
    write_assets(&mut x, target);
    write_scene_assets(&mut x);
    let _ = writeln!(x, "  <worldbody>");
    write_sun(&mut x, lab, kind);
    write_enclosure(&mut x, lab, kind);
    write_tripod_and_light(&mut x, lab, kind);
    if kind == SceneKind::Orbit {
        write_earth(&mut x, lab, &options.rtn_to_base);
    }
    write_target(&mut x, &(lab.base_in_lab() * lab.target_in_base()), target);
    crate::board::write_board(&mut x, lab).map_err(StubSceneError::Lab)?;
    write_arm(&mut x, lab);
    let _ = writeln!(x, "  </worldbody>");
    let _ = writeln!(x, "  <actuator>");
    for j in 0..DOF {
        let t = TORQUE_LIMIT[j];
        let _ = writeln!(
            x,
            "    <position name=\"{}\" joint=\"{}\" kp=\"{}\" kv=\"{}\" forcerange=\"{}\"/>",
            ACTUATOR_NAMES[j],
            JOINT_NAMES[j],
            nums(&[servo_kp(j)]),
            nums(&[servo_kv(j)]),
            nums(&[-t, t])
        );
    }
    let _ = writeln!(x, "  </actuator>");
    let _ = writeln!(x, "</mujoco>");
    Ok(x)
}

/// Rendering quality, clip and shadow settings, and the scene's fixed length scale.
fn write_visual(x: &mut String, lab: &LabConfig, target: &TargetModel) {
    let extent = scene_extent_m(lab);
    let (lo, hi) = lab.enclosure_box();
    let centre = (lo.coords + hi.coords) / 2.0;
    let _ = writeln!(
        x,
        "  <statistic extent=\"{}\" center=\"{}\"/>",
        nums(&[extent]),
        pos_attr(&centre)
    );
    // shadowclip: the directional Sun's shadow square, as a fraction of the extent;
    // shadowscale: the part of a spot light's beam its shadow map covers.
    let clip = shadow_half_size_m(target.greatest_dimension_m) / extent;
    let _ = writeln!(
        x,
        "  <visual>\n    <quality shadowsize=\"{SHADOW_MAP_SIZE}\"/>\n    <map shadowclip=\"{}\" shadowscale=\"{}\"/>\n  </visual>",
        nums(&[clip]),
        nums(&[SPOT_SHADOW_SCALE])
    );
}

/// Default classes: the arm, the enclosure's curtains, collision-only keep-outs, the target,
/// visual-only decor. In `orbit` the arm and the enclosure are collision only.
fn write_defaults(x: &mut String, kind: SceneKind) {
    let hidden = COLLISION_ONLY_GROUP;
    let (arm_group, curtain) = match kind {
        SceneKind::Lab => (1, "group=\"0\" material=\"curtain\"".to_string()),
        SceneKind::Orbit => (hidden, format!("group=\"{hidden}\"")),
    };
    let _ = write!(
        x,
        "  <default>\n\
         \x20   <default class=\"arm\">\n      <geom contype=\"1\" conaffinity=\"0\" group=\"{arm_group}\" rgba=\"0.85 0.85 0.85 1\"/>\n    </default>\n\
         \x20   <default class=\"curtain\">\n      <geom contype=\"0\" conaffinity=\"1\" {curtain}/>\n    </default>\n\
         \x20   <default class=\"keepout\">\n      <geom contype=\"0\" conaffinity=\"1\" group=\"{hidden}\" rgba=\"0.5 0.5 0.5 1\"/>\n    </default>\n\
         \x20   <default class=\"target\">\n      <geom contype=\"0\" conaffinity=\"1\" group=\"2\"/>\n    </default>\n\
         \x20   <default class=\"decor\">\n      <geom contype=\"0\" conaffinity=\"0\" group=\"0\"/>\n    </default>\n\
         \x20 </default>\n"
    );
}

/// Materials of the lab's and the orbit's own things (the target's are its own). The curtains
/// are black-out fabric: near black, faintly warm, matte (no specular, no reflectance). A fine
/// weave texture was tried and dropped: texturing every curtain pixel twice (MuJoCo's shadow
/// pass draws the scene again) cost a third of a 1280x800 frame in software.
fn write_scene_assets(x: &mut String) {
    x.push_str(
        "  <asset>\n\
         \x20   <material name=\"curtain\" rgba=\"0.065 0.062 0.06 1\" specular=\"0\" shininess=\"0\" reflectance=\"0\"/>\n\
         \x20   <material name=\"tripod\" rgba=\"0.12 0.12 0.13 1\" specular=\"0.35\" shininess=\"0.4\"/>\n\
         \x20   <material name=\"lamp\" rgba=\"0.08 0.08 0.08 1\" specular=\"0.5\" shininess=\"0.6\"/>\n\
         \x20   <material name=\"lamp-lens\" rgba=\"1 0.97 0.9 1\" emission=\"1\"/>\n\
         \x20   <texture name=\"earth-clouds\" type=\"cube\" builtin=\"gradient\" rgb1=\"0.35 0.55 0.95\" rgb2=\"0.04 0.12 0.4\" mark=\"random\" random=\"0.25\" markrgb=\"0.95 0.95 0.97\" width=\"256\" height=\"256\"/>\n\
         \x20   <material name=\"earth\" texture=\"earth-clouds\" specular=\"0.15\" shininess=\"0.2\" rgba=\"1 1 1 1\"/>\n\
         \x20 </asset>\n",
    );
}

/// The Sun: in `lab` the studio light, a spot at its configured position aimed at the target,
/// its beam falling off with distance (1 at the target); in `orbit` a directional light whose
/// direction the camera sets per capture (the default: from the light's position towards the
/// target). Both cast shadows.
fn write_sun(x: &mut String, lab: &LabConfig, kind: SceneKind) {
    let d = sun_direction_lab(lab);
    let pos = Vector3::from(lab.light.position_lab_m);
    match kind {
        SceneKind::Lab => {
            // attenuation 1 / (c0 + c2 d^2): the target, at distance r, gets 1; the beam's
            // far end (curtains) gets about (r / d)^2 of it.
            let r = (target_centre_lab(lab).coords - pos).norm().max(0.1);
            let _ = writeln!(
                x,
                "    <light name=\"{SUN_LIGHT}\" type=\"spot\" pos=\"{}\" dir=\"{}\" cutoff=\"{}\" exponent=\"{}\" attenuation=\"{}\" diffuse=\"1 1 1\" specular=\"0.4 0.4 0.4\" castshadow=\"true\"/>",
                pos_attr(&pos),
                pos_attr(&d),
                nums(&[SPOT_CUTOFF_DEG]),
                nums(&[SPOT_EXPONENT]),
                nums(&[0.2, 0.0, 0.8 / (r * r)])
            );
        }
        SceneKind::Orbit => {
            let _ = writeln!(
                x,
                "    <light name=\"{SUN_LIGHT}\" type=\"directional\" pos=\"{}\" dir=\"{}\" diffuse=\"1 1 1\" specular=\"0.5 0.5 0.5\" castshadow=\"true\"/>",
                pos_attr(&sun_shadow_position(lab, &d).coords),
                pos_attr(&d)
            );
        }
    }
}

/// Where the directional Sun's shadow camera sits for light travelling along `dir`: on the
/// target's Sun side at [`SUN_SHADOW_DISTANCE_M`], so its shadow map is centred on the target.
pub fn sun_shadow_position(lab: &LabConfig, dir: &Vector3<f64>) -> Point3<f64> {
    target_centre_lab(lab) - dir * SUN_SHADOW_DISTANCE_M
}

/// Distance from the target to the directional Sun's shadow camera, metres.
pub const SUN_SHADOW_DISTANCE_M: f64 = 3.0;

/// The Earth in `orbit`: a sphere along the nadir at [`EARTH_DISTANCE_M`], as large as the
/// Earth looks from the planner's default orbit.
fn write_earth(x: &mut String, lab: &LabConfig, rtn_to_base: &Matrix3<f64>) {
    let centre = target_centre_lab(lab) + nadir_lab(lab, rtn_to_base) * EARTH_DISTANCE_M;
    let radius = EARTH_DISTANCE_M * EARTH_ANGULAR_RADIUS_DEG.to_radians().sin();
    let _ = writeln!(
        x,
        "    <geom name=\"{EARTH_GEOM}\" class=\"decor\" type=\"sphere\" size=\"{}\" pos=\"{}\" material=\"earth\"/>",
        nums(&[radius]),
        pos_attr(&centre.coords)
    );
}

fn write_enclosure(x: &mut String, lab: &LabConfig, _kind: SceneKind) {
    let [sx, sy, sz] = lab.enclosure.size_m;
    let t = WALL_THICKNESS;
    let (hx, hy, hz) = (sx / 2.0 + t, sy / 2.0 + t, sz / 2.0 + t);
    type Wall = (&'static str, [f64; 3], [f64; 3]);
    let walls: [Wall; 6] = [
        ("floor", [sx / 2.0, sy / 2.0, -t / 2.0], [hx, hy, t / 2.0]),
        ("ceiling", [sx / 2.0, sy / 2.0, sz + t / 2.0], [hx, hy, t / 2.0]),
        ("wall-x-", [-t / 2.0, sy / 2.0, sz / 2.0], [t / 2.0, hy, hz]),
        ("wall-x+", [sx + t / 2.0, sy / 2.0, sz / 2.0], [t / 2.0, hy, hz]),
        ("wall-y-", [sx / 2.0, -t / 2.0, sz / 2.0], [hx, t / 2.0, hz]),
        ("wall-y+", [sx / 2.0, sy + t / 2.0, sz / 2.0], [hx, t / 2.0, hz]),
    ];
    for (name, c, h) in walls {
        let _ = writeln!(
            x,
            "    <geom name=\"{name}\" class=\"curtain\" type=\"box\" pos=\"{}\" size=\"{}\"/>",
            nums(&c),
            nums(&h)
        );
    }
}

/// The tripod (drawn in `lab`, collision only in `orbit`), the light's keep-out sphere (collision
/// only) and, in `lab`, the lamp's housing: a short dark cylinder behind the light's position,
/// out of its own beam and shadow camera, with a glowing lens.
fn write_tripod_and_light(x: &mut String, lab: &LabConfig, kind: SceneKind) {
    let base = lab.base_in_lab();
    for (name, c) in lab.keepouts_base() {
        let (a, b) = (base * c.a, base * c.b);
        match name {
            "tripod" if (b - a).norm() > 1e-9 && c.radius > 0.0 => {
                let look = match kind {
                    SceneKind::Lab => "class=\"curtain\" material=\"tripod\"",
                    SceneKind::Orbit => "class=\"keepout\"",
                };
                let _ = writeln!(
                    x,
                    "    <geom name=\"tripod\" {look} type=\"capsule\" size=\"{}\" fromto=\"{}\"/>",
                    nums(&[c.radius]),
                    nums(&[a.x, a.y, a.z, b.x, b.y, b.z])
                );
            }
            "light" if c.radius > 0.0 => {
                let _ = writeln!(
                    x,
                    "    <geom name=\"light\" class=\"keepout\" type=\"sphere\" size=\"{}\" pos=\"{}\"/>",
                    nums(&[c.radius]),
                    pos_attr(&a.coords)
                );
            }
            _ => {}
        }
    }
    if kind == SceneKind::Lab {
        let d = sun_direction_lab(lab);
        let p = Vector3::from(lab.light.position_lab_m);
        let (r, back, front) = (0.06, 0.14, 0.012);
        let (a, b) = (p - d * back, p - d * front);
        let _ = writeln!(
            x,
            "    <geom name=\"{LAMP_GEOM}\" class=\"decor\" type=\"cylinder\" size=\"{}\" fromto=\"{}\" material=\"lamp\"/>",
            nums(&[r]),
            nums(&[a.x, a.y, a.z, b.x, b.y, b.z])
        );
        let (a, b) = (p - d * front, p - d * (front - 0.002));
        let _ = writeln!(
            x,
            "    <geom name=\"lamp-lens\" class=\"decor\" type=\"cylinder\" size=\"{}\" fromto=\"{}\" material=\"lamp-lens\"/>",
            nums(&[0.85 * r]),
            nums(&[a.x, a.y, a.z, b.x, b.y, b.z])
        );
    }
}

fn write_arm(x: &mut String, lab: &LabConfig) {
    let geoms = arm_geoms(lab);
    let _ = writeln!(x, "    <body name=\"{BASE_BODY}\" {}>", frame_attrs(&lab.base_in_lab()));
    let mut indent = String::from("      ");
    for (_, name, a, b, r) in geoms.iter().filter(|g| g.0 == 0) {
        capsule_geom(x, &indent, name, a, b, *r);
    }
    for i in 1..=DOF {
        let offset = kinematics::body_offset(i - 1);
        let _ = writeln!(
            x,
            "{indent}<body name=\"{}\" {} gravcomp=\"1\">",
            LINK_BODIES[i - 1],
            frame_attrs(&offset)
        );
        indent.push_str("  ");
        let _ = writeln!(x, "{indent}{}", inertial(i));
        let (lo, hi) = lab.arm.joint_table.limits()[i - 1];
        let _ = writeln!(
            x,
            "{indent}<joint name=\"{}\" type=\"hinge\" axis=\"0 0 1\" range=\"{}\" armature=\"{}\" damping=\"{}\"/>",
            JOINT_NAMES[i - 1],
            nums(&[lo, hi]),
            nums(&[ARMATURE[i - 1]]),
            nums(&[JOINT_DAMPING])
        );
        for (_, name, a, b, r) in geoms.iter().filter(|g| g.0 == i) {
            capsule_geom(x, &indent, name, a, b, *r);
        }
        if i == DOF {
            let mount = lab.camera_mount();
            let t = pos_attr(&mount.translation.vector);
            let _ = writeln!(
                x,
                "{indent}<site name=\"{CAMERA_SITE}\" pos=\"{t}\" quat=\"{}\" size=\"0.005\"/>",
                quat_attr(&mount.rotation)
            );
            let _ = writeln!(
                x,
                "{indent}<camera name=\"{CAMERA_NAME}\" pos=\"{t}\" quat=\"{}\" fovy=\"45\"/>",
                quat_attr(&mujoco_camera_from_opencv(&mount.rotation))
            );
        }
    }
    for _ in 1..=DOF {
        indent.truncate(indent.len() - 2);
        let _ = writeln!(x, "{indent}</body>");
    }
    let _ = writeln!(x, "    </body>");
}
