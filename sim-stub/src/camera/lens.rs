//! The simulated camera's lens: a frame through a distortion is MuJoCo's (or the ray cast's)
//! pinhole render remapped, as OpenCV's `initUndistortRectifyMap` + `remap` would distort it.
//!
//! Both renderers draw a pinhole. For intrinsics with a [`Distortion`], [`LensMap::new`] works
//! out a pinhole *canvas* with the same focal lengths that covers every ray the distorted image
//! sees (a barrel lens sees further out than its pinhole: the canvas is larger), and for every
//! output pixel the canvas position of its ray ([`Intrinsics::unproject`], then the canvas's
//! pinhole). [`LensMap::remap`] then samples the canvas render there: colour bilinearly, depth
//! and mask at the nearest canvas pixel (a blend of two depths is a surface that is not there;
//! the mask stays the target's exact pixels, and depth and mask stay consistent). Depth is the
//! z-depth along the optical axis, which does not depend on where the lens puts the point, so the
//! sampled depth is the output pixel's depth. A ray beyond the canvas (only for lenses far
//! outside the lab configuration's range) sees nothing: black, no return, not the target.

use super::intrinsics::MAX_SIDE;
use super::render::Image;
use hitl_hal::{Distortion, Intrinsics};

/// Pixels of canvas kept beyond the outermost ray on every side (for the bilinear neighbour).
const MARGIN_PX: f64 = 2.0;
/// Largest canvas side as a multiple of the output's.
const MAX_GROWTH: f64 = 3.0;

/// Where each output pixel of a distorted camera reads the pinhole canvas.
#[derive(Debug, Clone, PartialEq)]
pub struct LensMap {
    /// The output (distorted) intrinsics this map is for.
    pub output: Intrinsics,
    /// The pinhole canvas to render.
    pub canvas: Intrinsics,
    /// Canvas position of each output pixel's ray, row-major.
    source: Vec<[f32; 2]>,
}

impl LensMap {
    /// The map for `output`; `None` for a pinhole (render it directly: no remap, no cost).
    pub fn new(output: &Intrinsics) -> Option<LensMap> {
        if output.distortion.is_none() {
            return None;
        }
        let (w, h) = (output.width, output.height);
        // The ideal (pinhole) pixels of the output's border: the image's edge is where the
        // furthest rays are, for every lens that does not fold the image over.
        let pinhole = |u: f64, v: f64| output.undistort_pixel(u, v);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let (right, bottom) = (f64::from(w) - 0.5, f64::from(h) - 0.5);
        let border = (0..=w)
            .flat_map(|i| {
                let u = f64::from(i) - 0.5;
                [(u, -0.5), (u, bottom)]
            })
            .chain((0..=h).flat_map(|j| {
                let v = f64::from(j) - 0.5;
                [(-0.5, v), (right, v)]
            }));
        for (u, v) in border {
            let (x, y) = pinhole(u, v);
            lo = [lo[0].min(x), lo[1].min(y)];
            hi = [hi[0].max(x), hi[1].max(y)];
        }
        let max_w = (f64::from(w) * MAX_GROWTH).min(f64::from(MAX_SIDE));
        let max_h = (f64::from(h) * MAX_GROWTH).min(f64::from(MAX_SIDE));
        let x0 = lo[0].max(-0.5 - (max_w - f64::from(w)) / 2.0) - MARGIN_PX;
        let y0 = lo[1].max(-0.5 - (max_h - f64::from(h)) / 2.0) - MARGIN_PX;
        let x1 = hi[0].min(right + (max_w - f64::from(w)) / 2.0) + MARGIN_PX;
        let y1 = hi[1].min(bottom + (max_h - f64::from(h)) / 2.0) + MARGIN_PX;
        // Canvas pixel 0's centre at output-pinhole position x0 + 0.5 (its left edge at x0).
        let (ox, oy) = ((x0 + 0.5).floor(), (y0 + 0.5).floor());
        let cw = ((x1 - ox).ceil() as u32).clamp(1, MAX_SIDE);
        let ch = ((y1 - oy).ceil() as u32).clamp(1, MAX_SIDE);
        let canvas =
            Intrinsics::pinhole(cw, ch, output.fx, output.fy, output.cx - ox, output.cy - oy);
        let mut source = Vec::with_capacity(w as usize * h as usize);
        for v in 0..h {
            for u in 0..w {
                let (x, y) = pinhole(f64::from(u), f64::from(v));
                source.push([(x - ox) as f32, (y - oy) as f32]);
            }
        }
        Some(LensMap { output: *output, canvas, source })
    }

    /// The distorted frame from the canvas's render `canvas` (drawn at [`Self::canvas`]).
    pub fn remap(&self, canvas: &Image) -> Image {
        let (cw, ch) = (self.canvas.width as usize, self.canvas.height as usize);
        let n = self.source.len();
        let mut color = vec![0u8; 3 * n];
        let mut depth_m = vec![0.0f32; n];
        let mut mask = vec![0u8; n];
        for (i, [sx, sy]) in self.source.iter().enumerate() {
            let (sx, sy) = (f64::from(*sx), f64::from(*sy));
            // Nearest: depth and mask.
            let (nx, ny) = (sx.round(), sy.round());
            if nx < 0.0 || ny < 0.0 || nx >= cw as f64 || ny >= ch as f64 {
                continue;
            }
            let j = ny as usize * cw + nx as usize;
            depth_m[i] = canvas.depth_m[j];
            mask[i] = canvas.mask[j];
            // Bilinear: colour (edges clamped).
            let (fx, fy) = (sx.floor(), sy.floor());
            let (ax, ay) = (sx - fx, sy - fy);
            let clamp_x = |x: f64| x.clamp(0.0, (cw - 1) as f64) as usize;
            let clamp_y = |y: f64| y.clamp(0.0, (ch - 1) as f64) as usize;
            let (x0, x1, y0, y1) = (clamp_x(fx), clamp_x(fx + 1.0), clamp_y(fy), clamp_y(fy + 1.0));
            for c in 0..3 {
                let at = |x: usize, y: usize| f64::from(canvas.color[3 * (y * cw + x) + c]);
                let top = at(x0, y0) * (1.0 - ax) + at(x1, y0) * ax;
                let bottom = at(x0, y1) * (1.0 - ax) + at(x1, y1) * ax;
                color[3 * i + c] = (top * (1.0 - ay) + bottom * ay).round().clamp(0.0, 255.0) as u8;
            }
        }
        Image { intrinsics: self.output, color, depth_m, mask }
    }
}

/// The last [`LensMap`] built, kept while the intrinsics stay the same (a run's do).
#[derive(Debug, Default)]
pub struct LensCache(Option<LensMap>);

impl LensCache {
    /// The map for `output` (`None`: a pinhole), built on first use.
    pub fn get(&mut self, output: &Intrinsics) -> Option<&LensMap> {
        if output.distortion.is_none() {
            return None;
        }
        if self.0.as_ref().is_none_or(|m| m.output != *output) {
            self.0 = LensMap::new(output);
        }
        self.0.as_ref()
    }
}

/// Why `distortion` cannot be rendered on `k`'s image, or `None` when it can: the lens must not
/// fold the image over (a ray seen at two pixels), which the remap cannot draw.
pub fn check(k: &Intrinsics, distortion: &Distortion) -> Option<String> {
    if !distortion.is_finite() {
        return Some(format!("distortion coefficients must be finite ({:?})", distortion.d()));
    }
    let lens = k.with_distortion(*distortion);
    let (w, h) = (f64::from(k.width) - 0.5, f64::from(k.height) - 0.5);
    for (u, v) in [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h), (w / 2.0, -0.5), (-0.5, h / 2.0)] {
        let (x, y) = lens.unproject(u, v);
        let (bu, bv) = lens.project(x, y, 1.0);
        if (bu - u).abs() > 0.01 || (bv - v).abs() > 0.01 {
            return Some(format!(
                "distortion {:?} folds the {}x{} image over at its edge (pixel ({u}, {v})): no lens \
                 does that; check the coefficients' order (k1, k2, p1, p2, k3)",
                distortion.d(),
                k.width,
                k.height
            ));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k() -> Intrinsics {
        Intrinsics::pinhole(64, 40, 50.0, 50.0, 31.5, 19.5)
    }

    #[test]
    fn a_pinhole_needs_no_map() {
        assert!(LensMap::new(&k()).is_none());
        assert!(LensCache::default().get(&k()).is_none());
    }

    #[test]
    fn a_barrel_lens_needs_a_larger_canvas_and_samples_it_where_the_ray_is() {
        let out = k().with_distortion(Distortion::brown_conrady([-0.25, 0.05, 0.0, 0.0, 0.0]));
        let m = LensMap::new(&out).expect("a lens");
        assert!(m.canvas.width > 64 && m.canvas.height > 40, "{:?}", m.canvas);
        assert!(m.canvas.distortion.is_none());
        // A canvas whose every pixel holds its own column in red, its row in depth: the output
        // pixel reads the column and row of its ray.
        let (cw, ch) = (m.canvas.width as usize, m.canvas.height as usize);
        let mut color = vec![0u8; 3 * cw * ch];
        let mut depth_m = vec![0.0f32; cw * ch];
        for y in 0..ch {
            for x in 0..cw {
                color[3 * (y * cw + x)] = x as u8;
                depth_m[y * cw + x] = y as f32;
            }
        }
        let canvas = Image { intrinsics: m.canvas, color, depth_m, mask: vec![255; cw * ch] };
        let img = m.remap(&canvas);
        assert_eq!(img.intrinsics, out);
        for (u, v) in [(0u32, 0u32), (63, 39), (31, 19), (10, 30)] {
            let (x, y) = out.unproject(f64::from(u), f64::from(v));
            let (cu, cv) = m.canvas.project(x, y, 1.0);
            let i = (v * 64 + u) as usize;
            assert!((f64::from(img.color[3 * i]) - cu).abs() <= 0.5 + 1e-6, "({u}, {v}) {cu}");
            assert_eq!(f64::from(img.depth_m[i]), cv.round(), "({u}, {v})");
            assert_eq!(img.mask[i], 255);
        }
        // The centre is (nearly) where the pinhole has it; the corner is pulled in from further
        // out than the pinhole image reaches.
        let (x, _) = out.unproject(0.0, 0.0);
        assert!(x * 50.0 + 31.5 < -0.5, "the corner's ray is beyond the pinhole's edge");
    }

    #[test]
    fn a_lens_that_folds_the_image_is_refused() {
        assert!(check(&k(), &Distortion::brown_conrady([-0.1, 0.0, 0.001, 0.0, 0.0])).is_none());
        let fold = Distortion::brown_conrady([-0.9, 0.0, 0.0, 0.0, 0.0]);
        assert!(check(&k(), &fold).is_some_and(|e| e.contains("folds")));
    }
}
