//! Protocol benchmarks against a running stub on loopback: what the project's client really
//! costs per servo setpoint and request round trips (on a stub without the box's command pacing,
//! so the figures are the client's and the link's), the command rate the stub serves (with the
//! box's pacing, as every stub runs), and the physics thread's real-time factor with nothing
//! rendering.

use super::{Stub, StubConfig, StubError};
use crate::plant::Plant;
use hitl_drivers::xarm::report::ReportKind;
use hitl_drivers::xarm::{ClientConfig, ServoReplies, XarmClient, XarmError};
use hitl_hal::{Arm, DOF};
use serde_json::{json, Value};
use std::time::{Duration, Instant};

/// Benchmark sizes.
#[derive(Debug, Clone, Copy)]
pub struct BenchOptions {
    /// Samples per latency figure.
    pub samples: usize,
    /// How long the command-rate flood runs.
    pub flood: Duration,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self { samples: 2000, flood: Duration::from_secs(1) }
    }
}

/// Why a benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Stub(#[from] StubError),
    #[error("benchmark client: {0}")]
    Client(#[from] XarmError),
}

fn micros(mut v: Vec<f64>) -> Value {
    v.sort_by(f64::total_cmp);
    let at = |p: f64| v.get(((v.len() as f64 - 1.0) * p).round() as usize).copied().unwrap_or(0.0);
    json!({
        "p50_us": at(0.5),
        "p99_us": at(0.99),
        "max_us": v.last().copied().unwrap_or(0.0),
        "samples": v.len(),
    })
}

/// Run the protocol benchmarks on a fresh stub around `plant` (ephemeral loopback ports).
pub fn bench_protocol(plant: Box<dyn Plant>, opts: BenchOptions) -> Result<Value, BenchError> {
    let config = StubConfig {
        report_ports: vec![(ReportKind::Real, 0)],
        max_command_rate_hz: None,
        ..StubConfig::ephemeral()
    };
    let q0 = config.initial_q;
    let stub = Stub::start(config, plant)?;
    let mut client = XarmClient::connect(stub.cmd_addr(), ClientConfig::default())?;
    client.enable_servo()?;
    let n = opts.samples.max(10);
    let pose = |i: usize| {
        let mut q = q0;
        q[0] += 0.05 * ((i as f64) * 0.01).sin();
        q
    };

    // servo_j as the official SDK does it: encode, send, wait for the reply.
    let mut wait = Vec::with_capacity(n);
    for i in 0..n {
        let t = Instant::now();
        client.servo_joint_wait(&pose(i))?;
        wait.push(t.elapsed().as_secs_f64() * 1e6);
    }
    // servo_j as the controller's tick does it (pipelined): drain replies, encode, send.
    let mut piped = Vec::with_capacity(n);
    for i in 0..n {
        let t = Instant::now();
        // Go on from where the waited stream ended: a jump back would be a speed error (24).
        client.servo_joint_pipelined(&pose(n + i), 10_000)?;
        piped.push(t.elapsed().as_secs_f64() * 1e6);
        std::thread::sleep(Duration::from_micros(200));
    }
    client.flush_servo_replies()?;
    // A request/reply the controller makes off the hot path.
    let mut get = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        client.joint_positions()?;
        get.push(t.elapsed().as_secs_f64() * 1e6);
    }
    // Command rate: stream servo_j as fast as the link takes them to a stub paced as a box is
    // (250 per second), then wait for every reply.
    let (served, flood_s) = flood(q0, opts.flood)?;
    client.set_servo_replies(ServoReplies::Wait);
    client.stop()?;
    let phys = stub.physics();
    let wait_mean = {
        let s: f64 = wait.iter().sum();
        s / wait.len() as f64
    };
    stub.shutdown();
    Ok(json!({
        "servo_j_round_trip": micros(wait),
        "servo_j_pipelined_call": micros(piped),
        "get_joints_round_trip": micros(get),
        "command_rate": {
            "pipelined_servo_j_per_s": served as f64 / flood_s,
            "box_limit_per_s": super::BOX_COMMAND_RATE_HZ,
            "unpaced_wait_servo_j_per_s": 1e6 / wait_mean,
        },
        "physics": {
            "dt_s": StubConfig::default().physics_dt,
            "steps": phys.steps,
            "late_steps": phys.late_steps,
            "realtime_factor": if phys.wall_s > 0.0 { phys.sim_s / phys.wall_s } else { 0.0 },
            "mean_step_us": phys.mean_step_s * 1e6,
            "max_realtime_factor": if phys.mean_step_s > 0.0 {
                StubConfig::default().physics_dt / phys.mean_step_s
            } else { 0.0 },
        },
    }))
}

/// A plant that is wherever it is told to be (the flood measures the command port only).
struct Follower(hitl_hal::Joints);

impl Plant for Follower {
    fn joints(&self) -> hitl_hal::Joints {
        self.0
    }
    fn velocities(&self) -> hitl_hal::Joints {
        [0.0; DOF]
    }
    fn command(&mut self, q: &hitl_hal::Joints) {
        self.0 = *q;
    }
    fn reset(&mut self, q: &hitl_hal::Joints) {
        self.0 = *q;
    }
    fn advance(&mut self, _dt: f64) {}
    fn time(&self) -> f64 {
        0.0
    }
    fn collision(&self) -> Option<crate::plant::Collision> {
        None
    }
}

/// Flood a stub paced like a box with pipelined servo_j for `span`; returns the setpoints it
/// took and the seconds until the last reply.
fn flood(q0: hitl_hal::Joints, span: Duration) -> Result<(u64, f64), BenchError> {
    let config = StubConfig {
        report_ports: vec![(ReportKind::Real, 0)],
        initial_q: q0,
        ..StubConfig::ephemeral()
    };
    let stub = Stub::start(config, Box::new(Follower(q0)))?;
    let mut client = XarmClient::connect(stub.cmd_addr(), ClientConfig::default())?;
    client.enable_servo()?;
    let before = stub.with_box(|b| b.servo_commands);
    let t = Instant::now();
    let mut i = 0u32;
    while t.elapsed() < span {
        let mut q = q0;
        q[0] += 1e-4 * f64::from(i % 100);
        client.servo_joint_pipelined(&q, 256)?;
        i += 1;
        if client.outstanding() >= 100 {
            client.flush_servo_replies()?;
        }
    }
    client.flush_servo_replies()?;
    let flood_s = t.elapsed().as_secs_f64();
    let served = stub.with_box(|b| b.servo_commands) - before;
    stub.shutdown();
    Ok((served, flood_s))
}
