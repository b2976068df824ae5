//! The simulated camera's benchmark (`hitl bench render`): frames per second of the ray-casting
//! renderer at 320x256 and 1280x1024, and trigger-to-frame latency through [`SimCamera`].

use super::{render_capture, FrameNoise, LightLevel, Preset, Renderer, SimCamera, SimCameraConfig};
use crate::mujoco_plant::{ArmSample, LabModel, SharedArmState};
use hitl_hal::{CaptureRequest, Clock, Joints, MonotonicClock, RgbdCamera};
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

fn frames_per_second(renderer: &mut Renderer, q: &Joints, w: u32, h: u32, frames: usize) -> f64 {
    let intr = Preset::Wfov.at(w, h);
    let start = Instant::now();
    for _ in 0..frames {
        let _ = render_capture(renderer, q, &intr, 1.0, &mut FrameNoise::none());
    }
    frames as f64 / start.elapsed().as_secs_f64()
}

/// Run the benchmark on the default lab and return its figures.
pub fn bench_render() -> serde_json::Value {
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
    let small = frames_per_second(&mut renderer, &q, 320, 256, 20);
    let large = frames_per_second(&mut renderer, &q, 1280, 1024, 3);
    // Trigger-to-frame latency through the camera's thread at 320x256.
    let clock = MonotonicClock::new();
    let arm = SharedArmState::new(ArmSample { q, sim_time_s: 0.0 });
    let config = SimCameraConfig {
        intrinsics: Preset::Wfov.at(320, 256),
        clock,
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
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().and_then(|v| v.parse::<f64>().ok()));
    json!({
        "renderer": "mj_multiRay ray casting",
        "threads": renderer.threads(),
        "loadavg_1m": load,
        "fps_320x256": small,
        "fps_1280x1024": large,
        "trigger_to_frame_ms_320x256": { "p50": pct(0.5), "p99": pct(0.99), "n": latencies_ms.len() },
    })
}
