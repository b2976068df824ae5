//! The tracker bench (`hitl bench tracker`): a clean fly-around is tracked and meets the goal, a
//! depth model that leaves no depth fails every frame and misses it, a bad target is an error.

use hitl_perception::testing::intrinsics_hfov;
use hitl_perception::tracker_bench::{run, TrackerBenchOptions};

fn options(targets: &[&str]) -> TrackerBenchOptions {
    TrackerBenchOptions {
        intrinsics: intrinsics_hfov(320, 200, 60.0),
        depth_model: "ideal".into(),
        rendered_mask: Some(2),
        targets: targets.iter().map(|t| t.to_string()).collect(),
        range_m: 10.0,
        frames: 6,
    }
}

#[test]
fn a_clean_fly_around_is_tracked_and_meets_the_goal() {
    let v = run(&options(&["asymmetric"]), None);
    let t = &v["targets"]["asymmetric"];
    assert_eq!(t["frames"], 6, "{v}");
    assert_eq!(t["failures"], 0, "{v}");
    assert!(t["mean_er_deg"].as_f64().expect("e_r") < 0.5, "{v}");
    assert!(t["et_over_range_pct"].as_f64().expect("e_t") < 0.1, "{v}");
    assert_eq!(t["goal"], "met", "{v}");
    assert_eq!(v["targets_met"], 1, "{v}");
    assert_eq!(v["mask"], "rendered, margin 2 px", "{v}");
    assert!((v["lab_range_m"].as_f64().expect("range") - 0.077).abs() < 1e-9, "{v}");
}

#[test]
fn no_depth_fails_every_frame_and_a_bad_target_is_an_error() {
    let blind = |_: u64, d: &mut [f32], _: &hitl_hal::Intrinsics| d.fill(0.0);
    let v = run(&options(&["asymmetric", "no-such-target"]), Some(&blind));
    let t = &v["targets"]["asymmetric"];
    assert_eq!(t["failures"], 6, "{v}");
    assert_eq!(t["goal"], "missed", "{v}");
    assert!(v["targets"]["no-such-target"]["error"].is_string(), "{v}");
    assert_eq!(v["targets_met"], 0, "{v}");
}
