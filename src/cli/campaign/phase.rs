//! A Sun phase window of a manifest (`sun_phase_deg = "FROM:TO"`, oriented phase in degrees, as
//! the paper's RQ4 regions are given) turned into the arc of argument of latitude `hitl plan
//! --arc` plays: the chaser's oriented Sun phase is sampled along the preset's relative orbit
//! (the planner's own ROE and phase functions, default chief and Sun), and the longest
//! contiguous stretch of u whose phase lies in the window is the arc.
//!
//! A phase-angle region of a manifest (`phase_angle_deg = "FROM:TO"`, the unsigned Sun-target-
//! chaser angle, 0-180 deg, as the paper's five regions of RQ4 are) keeps the case's arc and
//! chooses the Sun instead: of a set of directions covering the sphere, the one under which the
//! most of the arc sees a phase angle in the region (ties: the arc's mean nearest the region's
//! middle). The case's `hitl plan` gets it as `--sun-eci`, and the simulated Sun follows the
//! planned phase (docs/stub-scene.md).

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

/// Sun directions tried for a phase-angle region (a Fibonacci sphere: about 2.6 deg apart).
const SUN_CANDIDATES: usize = 6000;

/// Samples of the arc per degree of u for a phase-angle region.
const ARC_STEPS_PER_DEG: f64 = 2.0;

/// The unsigned phase angle (0-180 deg) of an oriented one (0-360).
pub fn phase_angle(oriented: f64) -> f64 {
    if oriented > 180.0 {
        360.0 - oriented
    } else {
        oriented
    }
}

/// The Sun a case plays under, and the phase angles its arc then sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaseSun {
    /// ECI direction (unit), as `hitl plan --sun-eci` takes it.
    pub sun_eci: [f64; 3],
    /// Least and greatest unsigned phase angle along the arc, degrees.
    pub phase_angle_deg: (f64, f64),
}

/// Unsigned phase angles along the arc `arc` (u, degrees) of `preset` at `range_m` under `sun`.
fn arc_phase_angles(preset: Preset, range_m: f64, arc: (f64, f64), sun: &Vector3<f64>) -> Vec<f64> {
    let chief = ChiefOrbit::default();
    let roe = preset.roe(range_m, chief.a_m);
    let u0 = chief.u0_rad();
    let n = (((arc.1 - arc.0) * ARC_STEPS_PER_DEG).ceil() as usize).max(1);
    (0..=n)
        .filter_map(|k| {
            let u = (arc.0 + (arc.1 - arc.0) * k as f64 / n as f64).to_radians();
            let rel = roe.position_rtn(chief.a_m, u, u0);
            orbit::sun_phase_deg(&chief, u, &rel, sun).map(phase_angle)
        })
        .collect()
}

/// The Sun of a case: under `region` (a phase-angle region, degrees in 0-180) the direction
/// chosen as the module says, else the planner's default. `arc`: the case's arc of u (default:
/// the whole orbit from the chief's u0). `Err` names the region when no direction keeps the
/// whole arc inside it.
pub fn case_sun(
    preset: &str,
    range_m: f64,
    arc: Option<(f64, f64)>,
    region: Option<(f64, f64)>,
) -> Result<CaseSun, String> {
    let p = Preset::from_name(preset)
        .ok_or_else(|| format!("preset {preset:?}: use flyaround or station-keeping"))?;
    let arc = arc.unwrap_or_else(|| {
        let from = ChiefOrbit::default().u0_rad().to_degrees();
        (from, from + 360.0)
    });
    let range_of = |a: &[f64]| {
        let lo = a.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = a.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (round3(lo), round3(hi))
    };
    let Some((from, to)) = region else {
        let sun = Vector3::from(orbit::DEFAULT_SUN_ECI);
        let a = arc_phase_angles(p, range_m, arc, &sun);
        return Ok(CaseSun { sun_eci: orbit::DEFAULT_SUN_ECI, phase_angle_deg: range_of(&a) });
    };
    let middle = 0.5 * (from + to);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut best: Option<(usize, f64, Vector3<f64>, Vec<f64>)> = None;
    for i in 0..SUN_CANDIDATES {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / SUN_CANDIDATES as f64;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let th = golden * i as f64;
        let sun = Vector3::new(r * th.cos(), r * th.sin(), z);
        let a = arc_phase_angles(p, range_m, arc, &sun);
        let inside = a.iter().filter(|&&x| (from..=to).contains(&x)).count();
        let off = (a.iter().sum::<f64>() / a.len().max(1) as f64 - middle).abs();
        let better = match &best {
            None => true,
            Some((n, o, _, _)) => inside > *n || (inside == *n && off < *o),
        };
        if better {
            best = Some((inside, off, sun, a));
        }
    }
    match best {
        Some((inside, _, sun, a)) if inside == a.len() && !a.is_empty() => Ok(CaseSun {
            sun_eci: [round6(sun.x), round6(sun.y), round6(sun.z)],
            phase_angle_deg: range_of(&a),
        }),
        _ => Err(format!(
            "no Sun direction keeps the phase angle of the {range_m}-m {preset} arc {}:{} deg \
             within {from}:{to} deg (a shorter arc sweeps fewer angles)",
            arc.0, arc.1
        )),
    }
}

fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
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
    fn a_sun_for_each_of_the_papers_phase_regions() {
        // The RQ4 preset's arc: 72 deg of u of the 50 m fly-around.
        let arc = Some((270.0, 342.0));
        for region in [(0.0, 36.0), (36.0, 72.0), (72.0, 108.0), (108.0, 144.0), (144.0, 180.0)] {
            let c = case_sun("flyaround", 50.0, arc, Some(region)).expect("a Sun");
            let (lo, hi) = c.phase_angle_deg;
            assert!(lo >= region.0 && hi <= region.1, "{region:?}: {lo}-{hi}");
            // Checked against the planner's phase function with the direction as it is passed.
            let chief = ChiefOrbit::default();
            let roe = Preset::Flyaround.roe(50.0, chief.a_m);
            let sun = Vector3::from(c.sun_eci);
            for u in [270.0f64, 306.0, 342.0] {
                let rel = roe.position_rtn(chief.a_m, u.to_radians(), chief.u0_rad());
                let p = phase_angle(
                    orbit::sun_phase_deg(&chief, u.to_radians(), &rel, &sun).expect("phase"),
                );
                assert!((region.0 - 0.01..=region.1 + 0.01).contains(&p), "{region:?} at {u}: {p}");
            }
        }
        // The default Sun over the whole orbit: the 135-225 deg oriented phases, 135-180 unsigned.
        let c = case_sun("flyaround", 50.0, None, None).expect("default");
        assert!(c.phase_angle_deg.0 > 130.0 && c.phase_angle_deg.1 <= 180.0, "{c:?}");
        // A region narrower than the arc's sweep under any Sun is refused, naming it.
        let e = case_sun("flyaround", 50.0, Some((0.0, 360.0)), Some((10.0, 11.0)))
            .expect_err("too narrow");
        assert!(e.contains("10:11"), "{e}");
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
