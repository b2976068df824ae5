//! Targets keep their materials in the MuJoCo-rendered camera: an OBJ's PNG texture shows its
//! own colours where its texture coordinates say, and the built-in spacecraft's gold bus and
//! blue solar arrays render in different colours. Small images (96x64) through the GL renderer.
#![cfg(feature = "stub")]

use hitl::devices::stub::stub_target;
use hitl_perception::TargetModel;
use hitl_sim_stub::camera::{GlRenderer, Image, Preset};
use hitl_sim_stub::mujoco_plant::LabModel;
use hitl_trajectories::lab::LabConfig;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

const W: u32 = 96;
const H: u32 = 64;

/// The default lab with `target` shown `size_m` across, a renderer, and the target's pose in
/// the lab.
fn scene(target: &TargetModel, size_m: f64) -> (GlRenderer, Isometry3<f64>) {
    let lab = LabConfig::default();
    let stub = stub_target(target, size_m / target.greatest_dimension_m());
    let model = LabModel::generated(&lab, &stub).expect("lab with the target");
    let mut gl = GlRenderer::new(model, W, H).expect("MuJoCo renderer (EGL)");
    gl.set_joints(&[0.0; 7]);
    (gl, lab.base_in_lab() * lab.target_in_base())
}

/// A camera `distance` from the target's centre along the target's `axis`, looking at it.
fn camera_on_axis(
    target_pose: &Isometry3<f64>,
    axis: Vector3<f64>,
    distance: f64,
) -> Isometry3<f64> {
    let centre = Point3::from(target_pose.translation.vector);
    let eye = centre + target_pose.rotation * axis * distance;
    let up = if (target_pose.rotation * axis).z.abs() > 0.9 { Vector3::x() } else { Vector3::z() };
    let look = UnitQuaternion::face_towards(&(centre - eye), &up);
    Isometry3::from_parts(Translation3::from(eye.coords), look)
}

/// Mean colour of the 3x3 pixels around where `p` (lab frame) projects.
fn colour_at(img: &Image, camera: &Isometry3<f64>, p: Point3<f64>) -> [f64; 3] {
    let c = camera.inverse() * p;
    let k = &img.intrinsics;
    let u = (k.cx + k.fx * c.x / c.z).round() as i64;
    let v = (k.cy + k.fy * c.y / c.z).round() as i64;
    assert!(u >= 1 && v >= 1 && u < i64::from(W) - 1 && v < i64::from(H) - 1, "({u},{v}) in view");
    let mut sum = [0.0; 3];
    for dv in -1..=1 {
        for du in -1..=1 {
            let i = ((v + dv) * i64::from(W) + u + du) as usize;
            assert_eq!(img.mask[i], 255, "pixel ({},{}) is on the target", u + du, v + dv);
            for (ch, s) in sum.iter_mut().enumerate() {
                *s += f64::from(img.color[3 * i + ch]) / 9.0;
            }
        }
    }
    sum
}

#[test]
fn an_obj_texture_shows_its_own_colours_where_its_coordinates_say() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/textured_cube/cube.obj");
    let target = TargetModel::from_spec(path).expect("textured cube");
    assert_eq!(target.parts.len(), 1);
    let size = 0.08;
    let (mut gl, pose) = scene(&target, size);
    // The top (+z) face carries the PNG's top-right quadrant (green); the side faces its
    // bottom-left (blue). A flipped v would show white on top, no texture plain white.
    let camera = camera_on_axis(&pose, Vector3::new(0.25, 0.0, 1.0).normalize(), 0.3);
    let img = gl.render_from(&camera, &Preset::Wfov.at(W, H), 1.0, [0.0, 0.0]).expect("render");
    let top = colour_at(&img, &camera, pose * Point3::new(0.0, 0.0, size / 2.0));
    assert!(top[1] > 40.0 && top[1] > 1.8 * top[0] && top[1] > 1.8 * top[2], "top face {top:?}");
    let side = colour_at(&img, &camera, pose * Point3::new(size / 2.0, 0.0, 0.0));
    assert!(side[2] > 1.8 * side[0] && side[2] > 1.3 * side[1], "+x face {side:?}");
}

#[test]
fn the_built_in_bus_and_solar_arrays_render_in_different_colours() {
    let target = TargetModel::from_spec("two-planes").expect("built-in");
    let names: Vec<&str> = target.parts.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["bus", "boom", "solar-array", "antenna"]);
    let size = 0.3;
    let scale = size / target.greatest_dimension_m();
    let (mut gl, pose) = scene(&target, size);
    let camera = camera_on_axis(&pose, Vector3::new(0.1, 0.3, 1.0).normalize(), 0.4);
    let img = gl.render_from(&camera, &Preset::Wfov.at(W, H), 1.0, [0.0, 0.0]).expect("render");
    // A point on the top face of each part, away from its edges (real metres, then lab).
    let top_of = |name: &str, fx: f64, fy: f64| -> Point3<f64> {
        let part = target.parts.iter().find(|p| p.name == name).expect(name);
        let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
        for v in &part.vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let x = lo[0] + fx * (hi[0] - lo[0]);
        let y = lo[1] + fy * (hi[1] - lo[1]);
        pose * Point3::new(x * scale, y * scale, hi[2] * scale)
    };
    // The bus's top corner (the dish covers its middle), the +x array's middle.
    let bus = colour_at(&img, &camera, top_of("bus", 0.9, 0.9));
    let array = colour_at(&img, &camera, top_of("solar-array", 0.85, 0.45));
    assert!(bus[0] > 40.0 && bus[0] > 1.5 * bus[2], "gold bus {bus:?}");
    assert!(array[2] > array[0] + 10.0, "blue array {array:?}");
    let gap = (0..3).map(|c| (bus[c] - array[c]).abs()).fold(0.0, f64::max);
    assert!(gap > 40.0, "bus {bus:?} and array {array:?} look alike");
}
