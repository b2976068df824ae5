//! The IK benchmark, run by hand (it times, so it is never part of the normal test run):
//!
//! `HITL_BENCH_IK_NPZ=/tmp/bench-ik.npz cargo test -p hitl-trajectories --release --test planner_bench -- --ignored --nocapture`
//!
//! prints `bench_ik(3600)` as JSON and, with the variable set, writes the same plan as NPZ for
//! `scripts/bench_ik.py`.

use hitl_trajectories::lab::LabConfig;
use hitl_trajectories::npz;
use hitl_trajectories::planner::{self, bench};

#[test]
#[ignore]
fn bench_ik_3600_waypoints() {
    let figures = bench::bench_ik(3600);
    println!("{figures}");
    assert_eq!(figures["solved"], 3600, "{figures}");
    if let Some(path) = std::env::var_os("HITL_BENCH_IK_NPZ") {
        let plan =
            planner::plan(&bench::bench_request(3600), &LabConfig::default(), &mut |_, _| {})
                .expect("plan");
        npz::save(std::path::Path::new(&path), &plan.trajectory, true).expect("save");
    }
}
