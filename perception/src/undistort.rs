//! A frame through a lens turned into the pinhole frame of the same camera: for backends whose
//! model of the camera is a pinhole `K` (the FoundationPose socket peer), which then see every
//! pixel where a pinhole with the frame's `K` would have seen it.
//!
//! Each output pixel reads the input where the lens put its ray ([`hitl_hal::Intrinsics::project`] of the
//! pinhole pixel's ray): colour bilinearly, depth and mask at the nearest pixel (a blend of two
//! depths is a surface that is not there; the mask keeps whole pixels and stays consistent with
//! the depth). Depth is the z-depth along the optical axis, the same wherever the lens puts the
//! point. An output pixel whose ray the input does not see gets no return, black, no target.
//! The pose a backend finds in the result is in the same camera frame as the input's.

use crate::PerceptionFrame;
use std::borrow::Cow;

/// `frame` as the pinhole with its `K` would see it: the frame itself (no copy) when its
/// intrinsics have no distortion.
pub fn to_pinhole(frame: &PerceptionFrame) -> Cow<'_, PerceptionFrame> {
    let k = frame.intrinsics;
    if k.distortion.is_none() {
        return Cow::Borrowed(frame);
    }
    let (w, h) = (k.width as usize, k.height as usize);
    let pinhole = k.pinhole_part();
    let mut depth_m = vec![0.0f32; w * h];
    let mut color = vec![0u8; if frame.color.is_empty() { 0 } else { 3 * w * h }];
    let mut mask = frame.mask.as_ref().map(|_| vec![0u8; w * h]);
    for v in 0..h {
        for u in 0..w {
            let (x, y) = pinhole.unproject(u as f64, v as f64);
            let (su, sv) = k.project(x, y, 1.0);
            let (nu, nv) = (su.round(), sv.round());
            if !(nu >= 0.0 && nv >= 0.0 && nu < w as f64 && nv < h as f64) {
                continue;
            }
            let (i, j) = (v * w + u, nv as usize * w + nu as usize);
            depth_m[i] = frame.depth_m[j];
            if let (Some(m), Some(src)) = (mask.as_mut(), frame.mask.as_ref()) {
                m[i] = src[j];
            }
            if !color.is_empty() {
                bilinear_rgb(&frame.color, (w, h), (su, sv), &mut color[3 * i..3 * i + 3]);
            }
        }
    }
    Cow::Owned(PerceptionFrame {
        intrinsics: pinhole,
        color: color.into(),
        depth_m: depth_m.into(),
        mask: mask.map(Into::into),
        ..frame.clone_header()
    })
}

/// The rgb8 image `src` (`w` x `h`) at `(x, y)`, bilinear, edges clamped.
fn bilinear_rgb(src: &[u8], (w, h): (usize, usize), (x, y): (f64, f64), out: &mut [u8]) {
    let (fx, fy) = (x.floor(), y.floor());
    let (ax, ay) = (x - fx, y - fy);
    let cx = |v: f64| v.clamp(0.0, (w - 1) as f64) as usize;
    let cy = |v: f64| v.clamp(0.0, (h - 1) as f64) as usize;
    let (x0, x1, y0, y1) = (cx(fx), cx(fx + 1.0), cy(fy), cy(fy + 1.0));
    for (c, o) in out.iter_mut().enumerate() {
        let at = |x: usize, y: usize| f64::from(src[3 * (y * w + x) + c]);
        let top = at(x0, y0) * (1.0 - ax) + at(x1, y0) * ax;
        let bottom = at(x0, y1) * (1.0 - ax) + at(x1, y1) * ax;
        *o = (top * (1.0 - ay) + bottom * ay).round().clamp(0.0, 255.0) as u8;
    }
}

impl PerceptionFrame {
    /// The frame's stamp and sequence number with no pixels.
    fn clone_header(&self) -> PerceptionFrame {
        PerceptionFrame {
            timestamp_ns: self.timestamp_ns,
            seq: self.seq,
            intrinsics: self.intrinsics,
            color: Vec::new().into(),
            depth_m: Vec::new().into(),
            mask: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hitl_hal::{Distortion, Intrinsics};

    fn frame(k: Intrinsics) -> PerceptionFrame {
        let n = (k.width * k.height) as usize;
        PerceptionFrame {
            timestamp_ns: 5,
            seq: 9,
            intrinsics: k,
            // Depth holds the pixel's column, the mask its row parity.
            depth_m: (0..n).map(|i| (i % k.width as usize) as f32).collect::<Vec<_>>().into(),
            color: (0..3 * n).map(|i| (i / 3 % k.width as usize) as u8).collect::<Vec<_>>().into(),
            mask: Some((0..n).map(|i| (i / k.width as usize % 2) as u8).collect::<Vec<_>>().into()),
        }
    }

    #[test]
    fn a_pinhole_frame_is_passed_as_it_is() {
        let f = frame(Intrinsics::pinhole(8, 6, 10.0, 10.0, 3.5, 2.5));
        assert!(matches!(to_pinhole(&f), Cow::Borrowed(_)));
    }

    #[test]
    fn each_pinhole_pixel_reads_where_the_lens_put_its_ray() {
        let k = Intrinsics::pinhole(64, 40, 50.0, 50.0, 31.5, 19.5)
            .with_distortion(Distortion::brown_conrady([-0.2, 0.05, 0.001, 0.0, 0.0]));
        let f = frame(k);
        let out = to_pinhole(&f);
        assert!(out.intrinsics.distortion.is_none());
        assert_eq!((out.intrinsics.fx, out.intrinsics.cx), (50.0, 31.5));
        assert_eq!((out.seq, out.timestamp_ns), (9, 5));
        for (u, v) in [(5usize, 5usize), (60, 35), (31, 19), (10, 30)] {
            let (x, y) = k.pinhole_part().unproject(u as f64, v as f64);
            let (su, sv) = k.project(x, y, 1.0);
            let i = v * 64 + u;
            assert_eq!(f64::from(out.depth_m[i]), su.round(), "({u}, {v})");
            assert_eq!(out.mask.as_ref().expect("mask")[i], (sv.round() as u8) % 2);
            assert!((f64::from(out.color[3 * i]) - su).abs() <= 0.5 + 1e-9, "({u}, {v}) {su}");
        }
        // Barrel: the lens squeezed the pinhole's corner inwards; it reads columns further in.
        assert!(out.depth_m[0] >= 2.0, "{}", out.depth_m[0]);
    }
}
