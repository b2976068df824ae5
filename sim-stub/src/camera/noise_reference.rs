//! Tests that the Orbbec model's faster code (issue 23: 10 Hz at 1280x800) models what it did
//! before: the model as first written (a copy of the clean depth, the shadows' columns rounded
//! by the C library, one viewpoint's shadows over the whole frame at a time) is kept here as the
//! reference, and both run on a synthetic scene with every case the model treats (a wall, a box
//! and a sphere casting shadows, a plane turned to grazing angles, depth nearer than the minimum
//! range, no return).

use super::*;

/// The model as first written (commit 221c3c0), the per-pass logic the fast code keeps.
fn reference(m: &StereoDepth, depth: &mut [f32], intr: &Intrinsics, rng: &mut Xoshiro256PlusPlus) {
    let (w, h) = (intr.width as usize, intr.height as usize);
    let clean = depth.to_vec();
    let mut invalid = vec![false; w * h];
    mark_edges(&clean, w, h, m.edge_jump, &mut invalid);
    for dx in [m.projector_x_m, m.baseline_m] {
        for v in 0..h {
            let row = v * w..(v + 1) * w;
            shadow_row(&clean[row.clone()], intr.fx * dx, m.edge_jump, &mut invalid[row]);
        }
    }
    mark_grazing(&clean, intr, m.grazing_deg, &mut invalid);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    for (d, bad) in depth.iter_mut().zip(&invalid) {
        let zf = f64::from(*d);
        if *bad || zf.is_nan() || zf < m.min_range_m {
            *d = 0.0;
            continue;
        }
        *d = (zf + m.sigma_m(zf) * unit.sample(rng)).max(m.min_range_m) as f32;
    }
}

/// The shadow of one row as first written: splat into the moved view's depth buffer, compare.
fn shadow_row(row: &[f32], fb: f64, jump: f64, invalid: &mut [bool]) {
    let w = row.len();
    let mut buf = vec![f64::INFINITY; w];
    let shifted: Vec<f64> =
        row.iter().enumerate().map(|(u, z)| u as f64 - fb / f64::from(*z)).collect();
    for u in 0..w {
        let a = f64::from(row[u]);
        if a <= 0.0 {
            continue;
        }
        let (mut lo, mut hi, mut near) = (shifted[u], shifted[u], a);
        if u + 1 < w {
            let b = f64::from(row[u + 1]);
            if b > 0.0 && (a - b).abs() <= jump * a.min(b) {
                let t = shifted[u + 1];
                (lo, hi, near) = (lo.min(t), hi.max(t), a.min(b));
            }
        }
        let (first, last) = (lo.round().max(0.0), hi.round().min(w as f64 - 1.0));
        if first <= last {
            for b in &mut buf[first as usize..=last as usize] {
                *b = b.min(near);
            }
        }
    }
    for u in 0..w {
        let (a, c) = (f64::from(row[u]), shifted[u].round());
        if a > 0.0 && c >= 0.0 && c < w as f64 && a > buf[c as usize] * (1.0 + jump) {
            invalid[u] = true;
        }
    }
}

/// 320x200 px, f = 200: a wall at 1.2 m; a box face at 0.7 m and a sphere (r 8 cm) at 0.5 m,
/// each shadowing the wall; a plane seen at 70-88 deg on the left (grazing); a patch nearer than
/// the minimum range; a strip with no return.
fn scene() -> (Vec<f32>, Intrinsics) {
    let (w, h) = (320usize, 200usize);
    let k = Intrinsics::pinhole(w as u32, h as u32, 200.0, 200.0, 159.5, 99.5);
    let mut d = vec![1.2f32; w * h];
    for v in 0..h {
        let y = (v as f64 - k.cy) / k.fy;
        for u in 0..w {
            let x = (u as f64 - k.cx) / k.fx;
            let i = v * w + u;
            if u < 60 {
                // A plane through 0.3 m on the strip's middle ray, its normal turned from that ray
                // by 70 deg at the top to 88 deg at the bottom: seen at 66-78 deg in rows 2-20,
                // at 80-89 deg (or not at all) in rows 175-188.
                let x0 = (30.0 - k.cx) / k.fx;
                let turn = x0.atan() + (70.0 + 18.0 * v as f64 / h as f64).to_radians();
                let (s, c) = turn.sin_cos();
                let d0 = 0.3 * (s * x0 + c);
                d[i] = (d0 / (s * x + c)).clamp(0.0, 5.0) as f32;
            }
            if (180..240).contains(&u) && (40..100).contains(&v) {
                d[i] = 0.7;
            }
            // Sphere: |t (x, y, 1) - c|^2 = r^2, nearest root.
            let (cx, cy, cz, r) = (-0.05, 0.08, 0.5, 0.08);
            let (a, b) = (x * x + y * y + 1.0, -2.0 * (x * cx + y * cy + cz));
            let disc = b * b - 4.0 * a * (cx * cx + cy * cy + cz * cz - r * r);
            if disc >= 0.0 {
                d[i] = d[i].min(((-b - disc.sqrt()) / (2.0 * a)) as f32);
            }
            if (280..300).contains(&u) && (150..170).contains(&v) {
                d[i] = 0.03;
            }
            if v >= 190 {
                d[i] = 0.0;
            }
        }
    }
    (d, k)
}

#[test]
fn the_fast_model_gives_the_reference_frames_exactly() {
    let (clean, k) = scene();
    let m = StereoDepth::GEMINI_305;
    for tick in [0u64, 1, 7] {
        let model =
            NoiseModel { seed: 11, depth_model: DepthModel::Orbbec(m), ..Default::default() };
        let mut fast = clean.clone();
        model.draw(tick).apply_depth(&mut fast, &k);
        let mut slow = clean.clone();
        let mut rng = model.draw(tick).depth_rng;
        reference(&m, &mut slow, &k, &mut rng);
        let differ = fast.iter().zip(&slow).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differ, 0, "tick {tick}: {differ} pixels differ from the reference");
    }
}

#[test]
fn the_fast_model_keeps_the_noise_and_the_dropouts() {
    let (clean, k) = scene();
    let (w, _) = (k.width as usize, k.height as usize);
    let model = NoiseModel {
        seed: 3,
        depth_model: DepthModel::Orbbec(StereoDepth::GEMINI_305),
        ..Default::default()
    };
    let mut d = clean.clone();
    model.draw(5).apply_depth(&mut d, &k);
    let dropped = |range: &dyn Fn(usize, usize) -> bool| {
        let (mut n, mut gone) = (0, 0);
        for (i, z) in d.iter().enumerate() {
            if range(i % w, i / w) {
                n += 1;
                gone += usize::from(*z == 0.0);
            }
        }
        gone as f64 / n as f64
    };
    // Noise on the wall away from everything: sigma = k z^2 = 0.02 * 1.44 = 28.8 mm.
    let wall: Vec<f64> = (10..30)
        .flat_map(|v| (80..170).map(move |u| v * w + u))
        .map(|i| f64::from(d[i]) - 1.2)
        .collect();
    let sd = (wall.iter().map(|e| e * e).sum::<f64>() / wall.len() as f64).sqrt();
    assert!((sd - 0.0288).abs() < 0.05 * 0.0288, "wall sigma {sd}");
    // The box's shadow on the wall: 200 * 0.018 * (1/0.7 - 1/1.2) = 2.1 px left of the box
    // (columns 178 and 179, the latter an edge too); the wall left of it keeps its depth.
    assert_eq!(dropped(&|u, v| (178..180).contains(&u) && (45..95).contains(&v)), 1.0, "shadow");
    assert_eq!(dropped(&|u, v| (170..177).contains(&u) && (45..95).contains(&v)), 0.0, "wall");
    assert_eq!(dropped(&|u, v| (190..230).contains(&u) && (50..90).contains(&v)), 0.0, "box face");
    // Grazing: all valid below 80 deg, none above.
    assert_eq!(dropped(&|u, v| (2..58).contains(&u) && (2..20).contains(&v)), 0.0, "66-78 deg");
    assert_eq!(dropped(&|u, v| (2..58).contains(&u) && (175..188).contains(&v)), 1.0, "80-89 deg");
    assert_eq!(dropped(&|u, v| (280..300).contains(&u) && (150..170).contains(&v)), 1.0, "near");
    assert_eq!(dropped(&|_, v| v >= 190), 1.0, "no return");
}
