//! The Orbbec depth model on a real render (the cube lab, MuJoCo's renderer, 160x128): the
//! cube's outline loses its depth, its top face keeps depth with the model's spread, and the
//! same seed and capture give the same image.

mod cube_lab;

use cube_lab::{cube_lab, HEIGHT, SIDE};
use hitl_sim_stub::camera::{DepthModel, GlRenderer, Image, NoiseModel, Preset, StereoDepth};

const W: usize = 160;
const H: usize = 128;

fn render(seed: u64, tick: u64) -> (Image, Vec<f32>) {
    let (model, camera, _) = cube_lab();
    let mut gl = GlRenderer::new(model, W as u32, H as u32).expect("MuJoCo renderer (EGL)");
    gl.set_joints(&[0.0; 7]);
    let mut img = gl
        .render_from(&camera, &Preset::Wfov.at(W as u32, H as u32), 1.0, [0.0, 0.0])
        .expect("render");
    let clean = img.depth_m.clone();
    let noise = NoiseModel {
        seed,
        depth_model: DepthModel::Orbbec(StereoDepth::GEMINI_305),
        ..NoiseModel::default()
    };
    noise.draw(tick).apply_depth(&mut img.depth_m, &img.intrinsics);
    (img, clean)
}

#[test]
fn the_outline_goes_and_the_face_keeps_the_model_spread() {
    let (img, clean) = render(1, 4);
    let on = |u: usize, v: usize| img.mask[v * W + u] == 255;
    let (mut outline, mut outline_invalid) = (0, 0);
    let mut face = Vec::new();
    for v in 2..H - 2 {
        for u in 2..W - 2 {
            if !on(u, v) {
                continue;
            }
            let i = v * W + u;
            let border = !(on(u - 1, v) && on(u + 1, v) && on(u, v - 1) && on(u, v + 1));
            let inner = (v - 2..=v + 2).all(|y| (u - 2..=u + 2).all(|x| on(x, y)));
            if border {
                outline += 1;
                outline_invalid += usize::from(img.depth_m[i] == 0.0);
            } else if inner {
                face.push(f64::from(img.depth_m[i] - clean[i]));
            }
        }
    }
    assert!(outline > 40, "outline pixels {outline}");
    assert_eq!(outline_invalid, outline, "every outline pixel invalid");
    assert!(face.len() > 200, "face pixels {}", face.len());
    let valid: Vec<f64> = face.iter().copied().filter(|e| e.abs() < 1.0).collect();
    assert_eq!(valid.len(), face.len(), "the face keeps its depth");
    let sd = (valid.iter().map(|e| e * e).sum::<f64>() / valid.len() as f64).sqrt();
    let z = HEIGHT - SIDE / 2.0;
    let want = StereoDepth::GEMINI_305.sigma_m(z);
    assert!((sd - want).abs() < 0.15 * want, "spread {sd} m, model {want} m at {z} m");
    // Seeded per capture.
    let (again, _) = render(1, 4);
    assert_eq!(img.depth_m, again.depth_m);
    let (other, _) = render(2, 4);
    assert_ne!(img.depth_m, other.depth_m);
}
