//! The monocular baseline's image side: which pixels show the lit target, FAST corners there
//! (imageproc), thinned to local maxima, their BRIEF descriptors (imageproc, one fixed set of
//! intensity tests so descriptors of different frames compare), and descriptor matching.

use super::MonoConfig;
use crate::PerceptionFrame;
use imageproc::binary_descriptors::brief::{brief, BriefDescriptor, TestPair};
use imageproc::binary_descriptors::BinaryDescriptor;
use imageproc::corners::corners_fast9;
use imageproc::image::GrayImage;
use imageproc::point::Point;
use imageproc::suppress::local_maxima;

/// Bits of a descriptor.
pub const DESCRIPTOR_BITS: usize = 256;

/// imageproc's BRIEF patch: 31 x 31 pixels about the corner.
const PATCH_RADIUS: u32 = 15;

/// Corners nearer the crop's edge than this have no full patch.
const BORDER: u32 = PATCH_RADIUS + 2;

/// Corners closer than this (pixels) to a stronger one are dropped.
const SUPPRESS_RADIUS: u32 = 3;

/// The corners of one frame and their descriptors; `pixels[i]` is `descriptors[i]`'s corner in
/// full-image pixels.
#[derive(Clone, Default)]
pub struct Features {
    pub pixels: Vec<(f64, f64)>,
    pub descriptors: Vec<BriefDescriptor>,
}

/// A window of the image, pixels (inclusive).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    pub u0: u32,
    pub v0: u32,
    pub u1: u32,
    pub v1: u32,
}

/// 8-bit luma of pixel `idx` of an rgb8 image (BT.601 weights).
fn luma(color: &[u8], idx: usize) -> u8 {
    let p = &color[idx * 3..idx * 3 + 3];
    ((77 * u32::from(p[0]) + 150 * u32::from(p[1]) + 29 * u32::from(p[2])) >> 8) as u8
}

/// Marks in `lit` (resized to the image) the pixels that show the lit target: inside the frame's
/// mask (every pixel without one) and brighter than `cfg.dark_level`. A camera sees no more of
/// the target than this: the shadowed side is as black as space. Returns the count and the
/// window holding them (`None`: no lit pixel).
pub fn lit_pixels(
    frame: &PerceptionFrame,
    cfg: &MonoConfig,
    lit: &mut Vec<u8>,
) -> (usize, Option<Window>) {
    let (w, h) = (frame.intrinsics.width as usize, frame.intrinsics.height as usize);
    lit.clear();
    lit.resize(w * h, 0);
    let (mut n, mut win) = (0usize, None::<Window>);
    for idx in 0..w * h {
        let in_mask = frame.mask.as_ref().is_none_or(|m| m[idx] != 0);
        if in_mask && luma(&frame.color, idx) > cfg.dark_level {
            lit[idx] = 255;
            n += 1;
            let (u, v) = ((idx % w) as u32, (idx / w) as u32);
            win = Some(match win {
                None => Window { u0: u, v0: v, u1: u, v1: v },
                Some(b) => {
                    Window { u0: b.u0.min(u), v0: b.v0.min(v), u1: b.u1.max(u), v1: b.v1.max(v) }
                }
            });
        }
    }
    (n, win)
}

/// The fixed BRIEF tests: pairs of points in the patch, each coordinate drawn about the patch
/// centre with a spread of a fifth of the patch (as BRIEF's isotropic Gaussian sampling), from a
/// fixed seed, so every run and every frame use the same tests.
pub fn test_pairs() -> Vec<TestPair> {
    let mut state = 0x5eed_b71e_f00d_u64;
    let mut next = move || {
        // splitmix64
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let diameter = 2 * PATCH_RADIUS + 1;
    let mut coord = move || loop {
        // Sum of four uniforms: close to a normal of standard deviation 0.577 x 2.
        let g = (next() + next() + next() + next() - 2.0) * 6.6 / 0.577;
        let c = (PATCH_RADIUS as f64 + g).round();
        if (0.0..diameter as f64).contains(&c) {
            return c as u32;
        }
    };
    (0..DESCRIPTOR_BITS)
        .map(|_| TestPair { p0: Point::new(coord(), coord()), p1: Point::new(coord(), coord()) })
        .collect()
}

/// Corners and descriptors of the lit target: the grey image of `window` (grown by the patch
/// border), FAST-9 corners above `cfg.fast_threshold` on lit pixels, local maxima only, the
/// `cfg.max_features` strongest.
pub fn detect(
    frame: &PerceptionFrame,
    lit: &[u8],
    window: Window,
    cfg: &MonoConfig,
    pairs: &[TestPair],
) -> Features {
    let (w, h) = (frame.intrinsics.width, frame.intrinsics.height);
    let u0 = window.u0.saturating_sub(BORDER);
    let v0 = window.v0.saturating_sub(BORDER);
    let u1 = (window.u1 + BORDER).min(w - 1);
    let v1 = (window.v1 + BORDER).min(h - 1);
    let (cw, ch) = (u1 - u0 + 1, v1 - v0 + 1);
    if cw <= 2 * BORDER || ch <= 2 * BORDER {
        return Features::default();
    }
    let grey = GrayImage::from_fn(cw, ch, |x, y| {
        let idx = (v0 + y) as usize * w as usize + (u0 + x) as usize;
        imageproc::image::Luma([luma(&frame.color, idx)])
    });
    let corners = local_maxima(&corners_fast9(&grey, cfg.fast_threshold), SUPPRESS_RADIUS);
    let mut kept: Vec<_> = corners
        .into_iter()
        .filter(|c| {
            (BORDER..cw - BORDER).contains(&c.x)
                && (BORDER..ch - BORDER).contains(&c.y)
                && lit[(v0 + c.y) as usize * w as usize + (u0 + c.x) as usize] != 0
        })
        .collect();
    kept.sort_by(|a, b| b.score.total_cmp(&a.score).then((a.y, a.x).cmp(&(b.y, b.x))));
    kept.truncate(cfg.max_features);
    let points: Vec<Point<u32>> = kept.iter().map(|c| Point::new(c.x, c.y)).collect();
    let pairs = pairs.to_vec();
    // Every point is inside the border, so imageproc has nothing to refuse.
    let Ok((descriptors, _)) = brief(&grey, &points, DESCRIPTOR_BITS, Some(&pairs)) else {
        return Features::default();
    };
    let pixels = points.iter().map(|p| (f64::from(u0 + p.x), f64::from(v0 + p.y))).collect();
    Features { pixels, descriptors }
}

/// For each of `query`'s descriptors the nearest of `reference` (Hamming distance), kept when it
/// is within `cfg.max_hamming` bits and clearly nearer than the second nearest (Lowe's ratio
/// `cfg.ratio`): pairs (query index, reference index).
pub fn match_descriptors(
    query: &[BriefDescriptor],
    reference: &[BriefDescriptor],
    cfg: &MonoConfig,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (i, q) in query.iter().enumerate() {
        let (mut best, mut second, mut at) = (u32::MAX, u32::MAX, 0);
        for (j, r) in reference.iter().enumerate() {
            let d = q.hamming_distance(r);
            if d < best {
                second = best;
                best = d;
                at = j;
            } else if d < second {
                second = d;
            }
        }
        if best <= cfg.max_hamming && f64::from(best) < cfg.ratio * f64::from(second) {
            out.push((i, at));
        }
    }
    out
}
