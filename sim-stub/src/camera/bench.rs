//! The simulated camera's benchmark (`hitl bench render`): frames per second of colour + depth +
//! mask from MuJoCo's renderer and from the ray cast, side by side in the same run, at 320x256,
//! 1280x800 and 1280x1024, idle and (with `load`) with every core busy; and trigger-to-frame
//! latency through [`SimCamera`]; and the wall and CPU time per frame of the camera's stages at
//! 1280x800 (render, Orbbec depth model).

use super::{
    capture_with, render_capture, DepthModel, FrameNoise, GlRenderer, LightLevel, NoiseModel,
    Preset, Renderer, SimCamera, SimCameraConfig, StereoDepth,
};
use crate::mujoco_plant::{ArmSample, LabModel, SharedArmState};
use hitl_hal::{CaptureRequest, Clock, Intrinsics, Joints, MonotonicClock, RgbdCamera};
use hitl_trajectories::kinematics::{camera_pose, first_joint_beyond_limits};
use hitl_trajectories::lab::LabConfig;
use serde_json::json;
use std::time::{Duration, Instant};

/// A pose of the arm, in the vertical plane through the base and the target (joints 2, 4 and 6
/// only), whose camera looks at the target from about `distance_m`: found by a coarse grid
/// search over the forward kinematics, refined by shrinking local grids. For benchmarks and tests.
pub fn look_at_target(lab: &LabConfig, distance_m: f64) -> Joints {
    let target = lab.target_position_base();
    let yaw = target.y.atan2(target.x);
    let mount = lab.camera_mount();
    let cost = |x: [f64; 3]| -> f64 {
        let q = [yaw, x[0], 0.0, x[1], 0.0, x[2], 0.0];
        if first_joint_beyond_limits(&q, &lab.arm.joint_table.limits(), 0.05).is_some() {
            return f64::INFINITY;
        }
        let cam = camera_pose(&q, &mount);
        let to = target - cam.translation.vector;
        let dist = to.coords.norm();
        let axis = cam.rotation * nalgebra::Vector3::z();
        let angle = (axis.dot(&to.coords) / dist).clamp(-1.0, 1.0).acos();
        angle + 2.0 * (dist - distance_m).abs()
    };
    let (lo, hi) = ([-1.2, 0.0, -1.5], [1.2, 2.8, 3.0]);
    let mut step: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]) / 12.0);
    let mut best = (lo, f64::INFINITY);
    let search = |centre: [f64; 3], half: i32, step: &[f64; 3], best: &mut ([f64; 3], f64)| {
        for i in -half..=half {
            for j in -half..=half {
                for k in -half..=half {
                    let x = [
                        centre[0] + f64::from(i) * step[0],
                        centre[1] + f64::from(j) * step[1],
                        centre[2] + f64::from(k) * step[2],
                    ];
                    let c = cost(x);
                    if c < best.1 {
                        *best = (x, c);
                    }
                }
            }
        }
    };
    let mid: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0);
    search(mid, 6, &step, &mut best);
    for _ in 0..6 {
        step = step.map(|s| s / 3.0);
        let centre = best.0;
        search(centre, 2, &step, &mut best);
    }
    let x = best.0;
    [yaw, x[0], 0.0, x[1], 0.0, x[2], 0.0]
}

/// Frames per second of `render` over about `seconds` (at least 2 frames).
fn frames_per_second(mut render: impl FnMut() -> bool, seconds: f64) -> Option<f64> {
    if !render() {
        return None; // the first frame (warm-up, context build) is not counted
    }
    let start = Instant::now();
    let mut frames = 0u32;
    while frames < 2 || start.elapsed().as_secs_f64() < seconds {
        if !render() {
            return None;
        }
        frames += 1;
    }
    Some(f64::from(frames) / start.elapsed().as_secs_f64())
}

/// The sizes the benchmark renders, with their intrinsics.
fn sizes() -> [(&'static str, Intrinsics); 3] {
    [
        ("320x256", Preset::Wfov.at(320, 256)),
        ("1280x800", Preset::Orbbec.at(1280, 800)),
        ("1280x1024", Preset::Wfov.at(1280, 1024)),
    ]
}

/// Frames/s of both renderers at every size, under whatever load is running.
fn figures(gl: &mut Option<GlRenderer>, ray: &mut Renderer, q: &Joints) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    for (name, intr) in sizes() {
        let mujoco = gl.as_mut().and_then(|gl| {
            frames_per_second(
                || capture_with(gl, q, &intr, 1.0, &mut FrameNoise::none()).is_ok(),
                2.0,
            )
        });
        let ray_cast = frames_per_second(
            || {
                let _ = render_capture(ray, q, &intr, 1.0, &mut FrameNoise::none());
                true
            },
            1.0,
        );
        let ratio = match (mujoco, ray_cast) {
            (Some(m), Some(r)) if r > 0.0 => Some(m / r),
            _ => None,
        };
        out.insert(
            name.into(),
            json!({ "mujoco_fps": mujoco, "ray_cast_fps": ray_cast, "mujoco_over_ray_cast": ratio }),
        );
    }
    serde_json::Value::Object(out)
}

/// CPU time this process has used so far (every thread, live or ended: user + system),
/// milliseconds, from `/proc/self/stat` (10 ms resolution: measure over several frames); `None`
/// off Linux. Next to wall time it says what a stage costs on a loaded machine, where wall time
/// also counts the waits for a core.
pub fn process_cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
    let rest = stat.rsplit_once(')')?.1;
    let mut fields = rest.split_whitespace().skip(11);
    let ticks: f64 = fields.next()?.parse::<f64>().ok()? + fields.next()?.parse::<f64>().ok()?;
    // USER_HZ is 100 on every Linux this runs on.
    Some(ticks * 10.0)
}

/// Wall and CPU milliseconds per call of `stage` over `frames` calls (after one not counted).
fn stage_ms(frames: u32, mut stage: impl FnMut(u64)) -> serde_json::Value {
    stage(0);
    let (t0, c0) = (Instant::now(), process_cpu_ms());
    for tick in 1..=u64::from(frames) {
        stage(tick);
    }
    let n = f64::from(frames.max(1));
    let wall = t0.elapsed().as_secs_f64() * 1e3 / n;
    let cpu = process_cpu_ms().zip(c0).map(|(c1, c0)| (c1 - c0) / n);
    json!({ "wall_ms": wall, "cpu_ms": cpu, "frames": frames })
}

/// The simulated camera's stages at the Orbbec's 1280x800, one frame of the scene at a time:
/// MuJoCo's render (colour, depth, mask: the render thread and the renderer's own threads), and
/// the Orbbec depth model (`--depth-model orbbec`) as the readout thread applies it; wall and
/// CPU milliseconds per frame (issue 23: both have 100 ms a frame at 10 Hz, on their own
/// threads).
fn stages_1280x800(
    gl: &mut Option<GlRenderer>,
    ray: &mut Renderer,
    q: &Joints,
) -> serde_json::Value {
    let intr = Preset::Orbbec.at(1280, 800);
    let mut depth = None;
    let render = gl.as_mut().map(|gl| {
        stage_ms(10, |_| {
            if let Ok((image, _)) = capture_with(gl, q, &intr, 1.0, &mut FrameNoise::none()) {
                depth = Some(image.depth_m);
            }
        })
    });
    let image = match depth {
        Some(d) => d,
        None => render_capture(ray, q, &intr, 1.0, &mut FrameNoise::none()).0.depth_m,
    };
    let model = NoiseModel {
        depth_model: DepthModel::Orbbec(StereoDepth::GEMINI_305),
        ..NoiseModel::default()
    };
    let mut copy = image.clone();
    let depth_model = stage_ms(20, |tick| {
        copy.copy_from_slice(&image);
        model.draw(tick).apply_depth(&mut copy, &intr);
    });
    json!({ "mujoco_render": render, "orbbec_depth_model": depth_model })
}

/// Runs the closure it is handed with every core busy (the caller's load generator).
pub type UnderLoad<'a> = &'a dyn Fn(&mut dyn FnMut());

/// Run the benchmark on the default lab and return its figures. `under_load`, when given, runs
/// the closure it is handed with every core busy (the controller's one load generator, so the
/// figures mean what its other benchmarks' "under load" mean); the figures then have a loaded row.
pub fn bench_render(under_load: Option<UnderLoad<'_>>) -> serde_json::Value {
    let lab = LabConfig::default();
    let model = match LabModel::new(&lab, None) {
        Ok(m) => m,
        Err(e) => return json!({ "error": e.to_string() }),
    };
    let q = look_at_target(&lab, 0.3);
    let mut renderer = match Renderer::new(model.clone()) {
        Ok(r) => r,
        Err(e) => return json!({ "error": e }),
    };
    let (mut gl, gl_error) = match GlRenderer::new(model.clone(), 320, 256) {
        Ok(gl) => (Some(gl), None),
        Err(e) => (None, Some(e.to_string())),
    };
    let idle = figures(&mut gl, &mut renderer, &q);
    let stages = stages_1280x800(&mut gl, &mut renderer, &q);
    let loaded = under_load.map(|run| {
        let mut f = serde_json::Value::Null;
        run(&mut || f = figures(&mut gl, &mut renderer, &q));
        f
    });
    drop(gl);
    // Trigger-to-frame latency through the camera's thread at 320x256.
    let clock = MonotonicClock::new();
    let arm = SharedArmState::new(ArmSample { q, sim_time_s: 0.0 });
    let config = SimCameraConfig {
        intrinsics: Preset::Wfov.at(320, 256),
        clock: clock.clone(),
        ..SimCameraConfig::default()
    };
    let mut latencies_ms = Vec::new();
    if let Ok(mut camera) = SimCamera::new(model, arm, LightLevel::new(1.0), config) {
        let _ = camera.arm_trigger();
        for tick in 0..20u64 {
            let fired_ns = clock.now_ns();
            if camera.trigger(CaptureRequest { tick, fired_ns }).is_err() {
                continue;
            }
            let deadline = Instant::now() + Duration::from_secs(10);
            while Instant::now() < deadline {
                if let Ok(Some(_)) = camera.poll_frame() {
                    latencies_ms.push((clock.now_ns() - fired_ns) as f64 / 1e6);
                    break;
                }
                std::thread::sleep(Duration::from_micros(200));
            }
        }
    }
    latencies_ms.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        latencies_ms
            .get(((latencies_ms.len() as f64 - 1.0) * p).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    // The machine's load when measured: the figures scale with the cores actually free.
    let loadavg = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().and_then(|v| v.parse::<f64>().ok()));
    json!({
        "bench": "render",
        "what": "frames/s of colour + depth + mask, the arm looking at the target from 0.3 m",
        "mujoco": "MuJoCo's OpenGL renderer, offscreen EGL (two passes: scene, target alone)",
        "mujoco_error": gl_error,
        "ray_cast": "mj_multiRay, one ray per pixel",
        "ray_cast_threads": renderer.threads(),
        "cores": std::thread::available_parallelism().map_or(0, |n| n.get()),
        "loadavg_1m": loadavg,
        "idle": idle,
        "load": loaded,
        "stages_1280x800": stages,
        "trigger_to_frame_ms_320x256": { "p50": pct(0.5), "p99": pct(0.99), "n": latencies_ms.len() },
    })
}
