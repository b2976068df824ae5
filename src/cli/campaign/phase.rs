//! A Sun phase window of a manifest (`sun_phase_deg = "FROM:TO"`, oriented phase in degrees, as
//! the paper's RQ4 regions are given) turned into the arc of argument of latitude `hitl plan
//! --arc` plays: the chaser's oriented Sun phase is sampled along the preset's relative orbit
//! (the planner's own ROE and phase functions, default chief and Sun), and the longest
//! contiguous stretch of u whose phase lies in the window is the arc.

use hitl_trajectories::orbit::{self, ChiefOrbit, Preset};
use nalgebra::Vector3;

/// Samples per degree of u.
const STEPS_PER_DEG: usize = 20;

/// Whether `phase` (in [0, 360)) lies in the window `from..to` degrees; a window with
/// `from > to` (e.g. 356:23.8) wraps through 0.
pub fn in_window(phase: f64, (from, to): (f64, f64)) -> bool {
    let (a, b) = (from.rem_euclid(360.0), to.rem_euclid(360.0));
    if to - from >= 360.0 {
        return true;
    }
    if a <= b {
        (a..=b).contains(&phase)
    } else {
        phase >= a || phase <= b
    }
}

/// The arc of u, degrees `(from, to)` with `from < to <= from + 360`, over which the `preset`'s
/// chaser at `range_m` sees the Sun at an oriented phase inside `window`; `Err` names the window
/// when no part of the orbit does.
pub fn arc_for_window(
    preset: &str,
    range_m: f64,
    window: (f64, f64),
) -> Result<(f64, f64), String> {
    let preset = Preset::from_name(preset)
        .ok_or_else(|| format!("preset {preset:?}: use flyaround or station-keeping"))?;
    let chief = ChiefOrbit::default();
    let roe = preset.roe(range_m, chief.a_m);
    let u0 = chief.u0_rad();
    let sun = Vector3::from(orbit::DEFAULT_SUN_ECI);
    let n = 360 * STEPS_PER_DEG;
    let step = 1.0 / STEPS_PER_DEG as f64;
    let inside: Vec<bool> = (0..n)
        .map(|k| {
            let u = u0 + (k as f64 * step).to_radians();
            let rel = roe.position_rtn(chief.a_m, u, u0);
            orbit::sun_phase_deg(&chief, u, &rel, &sun).is_some_and(|p| in_window(p, window))
        })
        .collect();
    if inside.iter().all(|&x| x) {
        let from = u0.to_degrees();
        return Ok((from, from + 360.0));
    }
    // Longest cyclic run of `true`: start scanning just after a `false`.
    let Some(first_out) = inside.iter().position(|&x| !x) else {
        return Err("no sample".into());
    };
    let (mut best, mut run_start, mut run_len) = ((0usize, 0usize), 0usize, 0usize);
    for j in 1..=n {
        let k = (first_out + j) % n;
        if inside[k] {
            if run_len == 0 {
                run_start = k;
            }
            run_len += 1;
            if run_len > best.1 {
                best = (run_start, run_len);
            }
        } else {
            run_len = 0;
        }
    }
    if best.1 < 2 {
        return Err(format!(
            "no part of the {}-m {} orbit sees the Sun at an oriented phase in {}:{} deg",
            range_m,
            preset.name(),
            window.0,
            window.1
        ));
    }
    let from = u0.to_degrees() + best.0 as f64 * step;
    let to = from + (best.1 - 1) as f64 * step;
    Ok((round3(from), round3(to)))
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_wrap_through_zero() {
        assert!(in_window(10.0, (356.0, 23.8)));
        assert!(in_window(357.0, (356.0, 23.8)));
        assert!(!in_window(180.0, (356.0, 23.8)));
        assert!(in_window(200.0, (165.8, 211.6)));
        assert!(!in_window(100.0, (165.8, 211.6)));
        assert!(in_window(100.0, (0.0, 360.0)));
    }

    #[test]
    fn the_arc_sees_the_window() {
        // With the planner's Sun (ECI +X) the 50 m fly-around sees oriented phases of 135-225 deg.
        for w in [(140.0, 160.0), (165.8, 194.4), (200.0, 220.0)] {
            let (from, to) = arc_for_window("flyaround", 50.0, w).expect("arc");
            assert!(to > from && to - from < 360.0, "{w:?}: {from}:{to}");
            let chief = ChiefOrbit::default();
            let roe = Preset::Flyaround.roe(50.0, chief.a_m);
            let sun = Vector3::from(orbit::DEFAULT_SUN_ECI);
            for s in [0.0, 0.5, 1.0] {
                let u = (from + s * (to - from)).to_radians();
                let rel = roe.position_rtn(chief.a_m, u, chief.u0_rad());
                let p = orbit::sun_phase_deg(&chief, u, &rel, &sun).expect("phase");
                assert!(in_window(p, (w.0 - 0.1, w.1 + 0.1)), "{w:?} at {s}: phase {p}");
            }
        }
        // The paper's region 2 does not occur on this orbit: refused, naming the window.
        let e = arc_for_window("flyaround", 50.0, (292.2, 337.3)).expect_err("no such stretch");
        assert!(e.contains("292.2:337.3"), "{e}");
        assert!(arc_for_window("warp", 50.0, (0.0, 10.0)).is_err());
    }
}
