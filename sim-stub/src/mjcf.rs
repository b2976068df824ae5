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

use crate::mujoco_plant::StubSceneError;
use crate::target_look::{write_assets, write_target};
pub use crate::target_look::{
    TargetMaterial, TargetModel, TargetPart, TargetTexture, TriangleMesh,
};
use hitl_trajectories::kinematics::{self, CHAIN, DOF, LINK_RADII};
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
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
/// The directional light that plays the Sun.
pub const SUN_LIGHT: &str = "sun";

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

fn frame_attrs(pose: &Isometry3<f64>) -> String {
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

/// The whole lab as an MJCF document.
pub fn lab_mjcf(lab: &LabConfig, target: &TargetModel) -> Result<String, StubSceneError> {
    lab.validate().map_err(|e| StubSceneError::Lab(e.to_string()))?;
    target.validate()?;
    let mut x = String::with_capacity(16 * 1024);
    let _ = writeln!(x, "<mujoco model=\"hitl-lab\">");
    let _ = writeln!(x, "  <compiler angle=\"radian\" autolimits=\"true\"/>");
    let _ = writeln!(
        x,
        "  <option timestep=\"{}\" gravity=\"0 0 -9.81\" integrator=\"implicitfast\"/>",
        nums(&[TIMESTEP_S])
    );
    x.push_str(
        "  <default>\n    <default class=\"arm\">\n      <geom contype=\"1\" conaffinity=\"0\" group=\"1\" rgba=\"0.85 0.85 0.85 1\"/>\n    </default>\n    <default class=\"scene\">\n      <geom contype=\"0\" conaffinity=\"1\" group=\"0\" rgba=\"0.03 0.03 0.03 1\"/>\n    </default>\n    <default class=\"target\">\n      <geom contype=\"0\" conaffinity=\"1\" group=\"2\"/>\n    </default>\n  </default>\n",
    );
    write_assets(&mut x, target);
    let _ = writeln!(x, "  <worldbody>");
    write_sun(&mut x, lab);
    write_enclosure(&mut x, lab);
    write_tripod_and_light(&mut x, lab);
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

fn write_sun(x: &mut String, lab: &LabConfig) {
    let d = sun_direction_lab(lab);
    let _ = writeln!(
        x,
        "    <light name=\"{SUN_LIGHT}\" type=\"directional\" pos=\"{}\" dir=\"{}\" diffuse=\"1 1 1\" castshadow=\"true\"/>",
        nums(&lab.light.position_lab_m),
        pos_attr(&d)
    );
}

fn write_enclosure(x: &mut String, lab: &LabConfig) {
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
            "    <geom name=\"{name}\" class=\"scene\" type=\"box\" pos=\"{}\" size=\"{}\"/>",
            nums(&c),
            nums(&h)
        );
    }
}

fn write_tripod_and_light(x: &mut String, lab: &LabConfig) {
    let base = lab.base_in_lab();
    for (name, c) in lab.keepouts_base() {
        let (a, b) = (base * c.a, base * c.b);
        match name {
            "tripod" if (b - a).norm() > 1e-9 && c.radius > 0.0 => {
                let _ = writeln!(
                    x,
                    "    <geom name=\"tripod\" class=\"scene\" type=\"capsule\" size=\"{}\" fromto=\"{}\" rgba=\"0.15 0.15 0.15 1\"/>",
                    nums(&[c.radius]),
                    nums(&[a.x, a.y, a.z, b.x, b.y, b.z])
                );
            }
            "light" if c.radius > 0.0 => {
                let _ = writeln!(
                    x,
                    "    <geom name=\"light\" class=\"scene\" type=\"sphere\" size=\"{}\" pos=\"{}\" rgba=\"0.2 0.2 0.2 1\"/>",
                    nums(&[c.radius]),
                    pos_attr(&a.coords)
                );
            }
            _ => {}
        }
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
