//! The plant follows a 250 Hz servo stream like a box in servo mode, stops at its joint limits,
//! and reports contacts with the enclosure and the tripod by name.

use hitl_sim_stub::mujoco_plant::MujocoPlant;
use hitl_sim_stub::plant::Plant;
use hitl_trajectories::kinematics::DOF;
use hitl_trajectories::lab::LabConfig;
use std::f64::consts::{FRAC_PI_2, PI};

const PERIOD: f64 = 0.004;

fn plant_at(q: &[f64; DOF]) -> MujocoPlant {
    let mut p = MujocoPlant::new(&LabConfig::default(), None).expect("plant");
    p.reset(q);
    assert_eq!(p.collision(), None, "start pose must be clear: {:?}", p.collisions());
    p
}

/// Stream `path(t)` for `duration` seconds at 250 Hz; returns (t, commanded, measured) per tick.
fn stream(
    p: &mut MujocoPlant,
    duration: f64,
    path: impl Fn(f64) -> [f64; DOF],
) -> Vec<(f64, [f64; DOF], [f64; DOF])> {
    let t0 = p.time();
    let n = (duration / PERIOD).round() as usize;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 * PERIOD;
        let q = path(t);
        p.command(&q);
        p.advance(PERIOD);
        out.push((p.time() - t0, q, p.joints()));
    }
    out
}

#[test]
fn follows_a_smooth_stream_with_a_small_lag() {
    let q0 = [0.0, -0.3, 0.0, 1.0, 0.0, 1.3, 0.0];
    let mut p = plant_at(&q0);
    let amp = [0.4, 0.3, 0.4, 0.3, 0.5, 0.4, 0.6];
    let cycle = 2.0;
    let path = |t: f64| -> [f64; DOF] {
        let s = if t < cycle { (1.0 - (2.0 * PI * t / cycle).cos()) / 2.0 } else { 0.0 };
        std::array::from_fn(|j| q0[j] + amp[j] * s)
    };
    let log = stream(&mut p, cycle + 0.5, path);
    assert!((p.time() - (cycle + 0.5)).abs() < 1e-9, "sim time {}", p.time());
    // Largest deviation from the command of the same tick.
    let max_dev = log
        .iter()
        .flat_map(|(_, c, m)| (0..DOF).map(move |j| (c[j] - m[j]).abs()))
        .fold(0.0, f64::max);
    // The lag: the delay that best explains the measured path as the delayed command.
    let err_at = |lag: f64| {
        log.iter()
            .filter(|(t, _, _)| *t > 0.2 && *t < cycle)
            .flat_map(|(t, _, m)| {
                let c = path(t - PERIOD - lag);
                (0..DOF).map(move |j| (c[j] - m[j]).abs())
            })
            .fold(0.0, f64::max)
    };
    let (lag, residual) = (0..=50)
        .map(|i| (f64::from(i) * 0.001, err_at(f64::from(i) * 0.001)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("lags");
    println!("max deviation {max_dev:.5} rad, lag {:.1} ms, residual {residual:.5} rad", lag * 1e3);
    assert!(max_dev < 0.02, "deviation {max_dev} rad");
    assert!(max_dev > 1e-4, "a real servo lags a little: {max_dev}");
    assert!(lag <= 0.025, "lag {lag} s");
    assert!(residual < 0.003, "measured path is not a delayed command: residual {residual}");
    // At rest again after the stream: back on the command, at standstill.
    let q = p.joints();
    let v = p.velocities();
    assert!((0..DOF).all(|j| (q[j] - q0[j]).abs() < 1e-3), "{q:?}");
    assert!(v.iter().all(|x| x.abs() < 1e-2), "{v:?}");
    assert_eq!(p.collision(), None);
}

#[test]
fn stops_at_a_joint_limit_and_says_which() {
    let q0 = [0.0, 0.0, 0.0, 0.6, 0.0, 0.9, 0.0];
    let mut p = plant_at(&q0);
    let lo = p.joint_limits()[3].0;
    let want = LabConfig::default().arm.joint_table.limits()[3].0;
    assert!((lo - want).abs() < 1e-9, "joint 4 lower limit {lo}, the lab's table says {want}");
    assert_eq!(p.joint_at_limit(0.01), None);
    // Ramp joint 4 to 0.3 rad beyond its lower limit at 0.8 rad/s.
    let goal = lo - 0.3;
    stream(&mut p, 2.0, |t| {
        let mut q = q0;
        q[3] = (q0[3] - 0.8 * t).max(goal);
        q
    });
    let q = p.joints();
    assert!((q[3] - lo).abs() < 0.02, "joint 4 at {} should rest on its limit {lo}", q[3]);
    assert_eq!(p.joint_at_limit(0.02).map(|x| x.0), Some(3));
    assert_eq!(p.collision(), None, "{:?}", p.collisions());
}

#[test]
fn sweeping_into_the_side_wall_reports_the_wall() {
    // Arm stretched out horizontally (0.84 m reach), pointing at the far end (-x, wall 0.9 m
    // away); turn joint 1 towards -y, where the wall is 0.61 m away.
    let start = [PI, 1.4167, 0.0, 2.81, 0.0, 0.5467, 0.0];
    let mut p = plant_at(&start);
    let mut hit = None;
    let log = stream(&mut p, 2.5, |t| {
        let mut q = start;
        q[0] = PI + (0.8 * t).min(FRAC_PI_2);
        q
    });
    assert!(!log.is_empty());
    for c in p.collisions() {
        hit.get_or_insert(c);
    }
    let hit = hit.expect("the arm must touch the wall");
    assert_eq!(hit.other, "wall-y-", "{hit:?}");
    assert!(!hit.arm_part.is_empty());
    // The wall holds the arm: joint 1 stays short of its command.
    assert!(p.joints()[0] < PI + FRAC_PI_2 - 0.02, "{:?}", p.joints());
}

#[test]
fn sweeping_into_the_tripod_reports_it() {
    // Arm reaching 0.5-0.57 m forward and low (nothing above 0.18 m at the tripod's distance,
    // the target's bottom is at 0.29 m); turn joint 1 from the side (+y) to the front.
    let start = [FRAC_PI_2, 0.6875, 0.0, 0.71, 0.0, -0.91, 0.0];
    let mut p = plant_at(&start);
    stream(&mut p, 3.0, |t| {
        let mut q = start;
        q[0] = (FRAC_PI_2 - 0.6 * t).max(0.0);
        q
    });
    let hits = p.collisions();
    assert!(
        hits.iter().any(|c| c.other == "tripod"),
        "expected the tripod among {hits:?} at {:?}",
        p.joints()
    );
}
