//! Runs the protocol benchmark (`hitl_sim_stub::bench_protocol`) and prints its figures, with the
//! MuJoCo lab plant (what `hitl stub` serves) and with the first-order test plant. Ignored by
//! default (figures, not pass/fail):
//! `cargo test --release -p hitl-sim-stub --test protocol_bench -- --ignored --nocapture`.

mod protocol_common;

use hitl_sim_stub::mujoco_plant::MujocoPlant;
use hitl_sim_stub::plant::Plant;
use hitl_sim_stub::{bench_protocol, BenchOptions};
use hitl_trajectories::lab::LabConfig;
use protocol_common::LagPlant;

fn run(name: &str, plant: Box<dyn Plant>) {
    let v = bench_protocol(plant, BenchOptions::default()).expect("benchmark runs");
    println!("{name}: {}", serde_json::to_string_pretty(&v).expect("json"));
    // Sanity, not speed targets: the figures exist and are positive.
    assert!(v["servo_j_round_trip"]["p50_us"].as_f64().expect("p50") > 0.0);
    assert!(v["command_rate"]["pipelined_servo_j_per_s"].as_f64().expect("rate") > 0.0);
    assert!(v["physics"]["max_realtime_factor"].as_f64().expect("rtf") > 0.0);
}

#[test]
#[ignore = "benchmark: run explicitly for figures"]
fn protocol_benchmark_figures() {
    let mujoco = MujocoPlant::new(&LabConfig::default(), None).expect("MuJoCo lab plant");
    run("mujoco", Box::new(mujoco));
    run("first-order", Box::new(LagPlant::new(None)));
}
