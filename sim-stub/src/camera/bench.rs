//! The simulated camera's benchmark (`hitl bench render`): frames per second of the ray-casting
//! renderer at 320x256 and 1280x1024, and trigger-to-frame latency through [`SimCamera`].

use super::{render_capture, FrameNoise, LightLevel, Preset, Renderer, SimCamera, SimCameraConfig};
use crate::mujoco_plant::{ArmSample, LabModel, SharedArmState};
use hitl_hal::{CaptureRequest, Clock, Joints, MonotonicClock, RgbdCamera, DOF};
use hitl_trajectories::kinematics::{camera_pose, first_joint_beyond_limits};
use hitl_trajectories::lab::LabConfig;
use serde_json::json;
use std::time::{Duration, Instant};

/// A pose of the arm, in the vertical plane through the base and the target (joints 2, 4 and 6
/// only), whose camera looks at the target from about `distance_m`: found by a grid search over
/// the forward kinematics. For benchmarks and tests.
pub fn look_at_target(lab: &LabConfig, distance_m: f64) -> Joints {
    let target = lab.target_position_base();
    let yaw = target.y.atan2(target.x);
    let mount = lab.camera_mount();
    let mut best = ([0.0; DOF], f64::INFINITY);
    let steps = 40;
    for a in 0..=steps {
        for b in 0..=steps {
            for c in 0..=steps {
                let f = |i: i32, lo: f64, hi: f64| lo + (hi - lo) * f64::from(i) / f64::from(steps);
                let q = [yaw, f(a, -1.2, 1.2), 0.0, f(b, 0.0, 2.8), 0.0, f(c, -1.5, 3.0), 0.0];
                if first_joint_beyond_limits(&q, 0.05).is_some() {
                    continue;
                }
                let cam = camera_pose(&q, &mount);
                let to = target - cam.translation.vector;
                let dist = to.coords.norm();
                let axis = cam.rotation * nalgebra::Vector3::z();
                let angle = (axis.dot(&to.coords) / dist).clamp(-1.0, 1.0).acos();
                let cost = angle + 2.0 * (dist - distance_m).abs();
                if cost < best.1 {
                    best = (q, cost);
                }
            }
        }
    }
    best.0
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
    json!({
        "renderer": "mj_multiRay ray casting, 1 thread",
        "fps_320x256": small,
        "fps_1280x1024": large,
        "trigger_to_frame_ms_320x256": { "p50": pct(0.5), "p99": pct(0.99), "n": latencies_ms.len() },
    })
}
