//! Orbbec frame metadata and bytes, as the SDK hands them over, checked and turned into the
//! HAL's colour (rgb8) and depth (metres) images. Pure functions over plain data: nothing here
//! trusts a size, format, scale or timestamp from the camera, and nothing panics on any input
//! (property tests below, and the fuzz target `orbbec_frame_meta`).

use hitl_hal::{Distortion, DistortionModel, ErrorKind, Intrinsics};

use super::error::OrbbecError;

/// `ob_format` values the driver accepts.
pub const FORMAT_Y16: i32 = 8;
pub const FORMAT_RGB: i32 = 22;
pub const FORMAT_Z16: i32 = 28;

/// The largest image side the driver accepts (the Gemini 305's largest stream is 1280 wide).
pub const MAX_SIDE: u32 = 8192;
/// Depth units larger than this many millimetres are not a depth scale.
pub const MAX_DEPTH_SCALE_MM: f32 = 100.0;

/// What the SDK says about one video frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameMeta {
    pub width: u32,
    pub height: u32,
    /// `ob_format`.
    pub format: i32,
    /// Device clock, microseconds.
    pub device_us: u64,
    /// Host arrival time (the SDK's system timestamp), microseconds on the SDK's host clock.
    pub system_us: u64,
    /// Exposure on the host clock (the SDK's global timestamp), microseconds; 0 until fitted.
    pub global_us: u64,
    /// Millimetres per depth unit (depth frames only).
    pub depth_scale_mm: f32,
}

/// One video frame copied out of the SDK.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RawImage {
    pub meta: FrameMeta,
    pub data: Vec<u8>,
}

/// A colour frame and the depth frame aligned to it, copied out of the SDK.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RawFrameset {
    pub color: Option<RawImage>,
    pub depth: Option<RawImage>,
}

fn bad(what: String) -> OrbbecError {
    OrbbecError::new(ErrorKind::DeviceFault, format!("Orbbec camera: {what}"))
}

/// `width * height * bytes_per_pixel`, refusing empty, oversized or overflowing images.
pub fn image_bytes(width: u32, height: u32, bytes_per_pixel: u32) -> Result<usize, OrbbecError> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(bad(format!("frame size {width}x{height} is outside 1..={MAX_SIDE}")));
    }
    usize::try_from(width)
        .ok()
        .and_then(|w| w.checked_mul(usize::try_from(height).ok()?))
        .and_then(|n| n.checked_mul(usize::try_from(bytes_per_pixel).ok()?))
        .ok_or_else(|| bad(format!("frame size {width}x{height} overflows")))
}

/// Check intrinsics the SDK reported for a `width x height` stream.
pub fn check_intrinsics(
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: u32,
    height: u32,
) -> Result<Intrinsics, OrbbecError> {
    image_bytes(width, height, 1)?;
    let ok = fx.is_finite()
        && fy.is_finite()
        && fx > 0.0
        && fy > 0.0
        && cx.is_finite()
        && cy.is_finite()
        && (0.0..=width as f32).contains(&cx)
        && (0.0..=height as f32).contains(&cy);
    if !ok {
        return Err(bad(format!(
            "colour intrinsics fx {fx} fy {fy} cx {cx} cy {cy} do not fit a {width}x{height} image"
        )));
    }
    Ok(Intrinsics {
        width,
        height,
        fx: f64::from(fx),
        fy: f64::from(fy),
        cx: f64::from(cx),
        cy: f64::from(cy),
        distortion: Default::default(),
    })
}

/// `ob_camera_distortion_model` values (ObTypes.h).
pub const OB_DISTORTION_NONE: i32 = 0;
pub const OB_DISTORTION_BROWN_CONRADY: i32 = 3;
pub const OB_DISTORTION_BROWN_CONRADY_K6: i32 = 4;

/// The lens distortion the SDK reported (`ob_camera_distortion`: `k1..k6`, `p1`, `p2`, model) as
/// the HAL's: Brown-Conrady as OpenCV's five coefficients, its K6 form as OpenCV's rational
/// model. The other models the SDK names (modified and inverse Brown-Conrady, Kannala-Brandt)
/// are refused: read as one of these, every projection would be wrong at the image's edges.
pub fn check_distortion(
    k: [f32; 6],
    p1: f32,
    p2: f32,
    model: i32,
) -> Result<Distortion, OrbbecError> {
    let c = |v: f32| f64::from(v);
    let lens = match model {
        OB_DISTORTION_NONE => Some(Distortion::NONE),
        OB_DISTORTION_BROWN_CONRADY => {
            Some(Distortion::brown_conrady([c(k[0]), c(k[1]), c(p1), c(p2), c(k[2])]))
        }
        OB_DISTORTION_BROWN_CONRADY_K6 => Distortion::from_d(
            DistortionModel::RationalPolynomial,
            &[c(k[0]), c(k[1]), c(p1), c(p2), c(k[2]), c(k[3]), c(k[4]), c(k[5])],
        ),
        other => {
            return Err(bad(format!(
                "colour lens distortion model {other} is not one hitl projects through (Brown-Conrady, \
                 {OB_DISTORTION_BROWN_CONRADY}, or its K6 form, {OB_DISTORTION_BROWN_CONRADY_K6})"
            )))
        }
    };
    lens.filter(Distortion::is_finite)
        .ok_or_else(|| bad(format!("colour lens distortion k {k:?} p1 {p1} p2 {p2} is not finite")))
}

/// The colour frame as rgb8 for `k` (exactly `width * height * 3` bytes, no row padding).
pub fn color_rgb8(img: &RawImage, k: &Intrinsics) -> Result<Vec<u8>, OrbbecError> {
    let m = &img.meta;
    if m.format != FORMAT_RGB {
        return Err(bad(format!(
            "colour frame has format {}, expected RGB ({FORMAT_RGB})",
            m.format
        )));
    }
    let want = image_bytes(m.width, m.height, 3)?;
    if (m.width, m.height) != (k.width, k.height) || img.data.len() != want {
        return Err(bad(format!(
            "colour frame {}x{} with {} bytes is not {}x{} rgb8 ({} bytes)",
            m.width,
            m.height,
            img.data.len(),
            k.width,
            k.height,
            image_bytes(k.width, k.height, 3).unwrap_or(0)
        )));
    }
    Ok(img.data.clone())
}

/// The depth frame (already aligned to colour) in metres for `k`; 0 stays 0 (no return).
pub fn depth_metres(img: &RawImage, k: &Intrinsics) -> Result<Vec<f32>, OrbbecError> {
    let m = &img.meta;
    if m.format != FORMAT_Y16 && m.format != FORMAT_Z16 {
        return Err(bad(format!(
            "depth frame has format {}, expected Y16 ({FORMAT_Y16}) or Z16 ({FORMAT_Z16})",
            m.format
        )));
    }
    let s = m.depth_scale_mm;
    if !(s.is_finite() && s > 0.0 && s <= MAX_DEPTH_SCALE_MM) {
        return Err(bad(format!("depth scale {s} mm per unit is not a depth scale")));
    }
    let want = image_bytes(m.width, m.height, 2)?;
    if (m.width, m.height) != (k.width, k.height) || img.data.len() != want {
        return Err(bad(format!(
            "depth frame {}x{} with {} bytes is not aligned to colour {}x{}",
            m.width,
            m.height,
            img.data.len(),
            k.width,
            k.height
        )));
    }
    Ok(y16_to_metres(&img.data, s))
}

/// Little-endian 16-bit depth units to metres (`scale_mm` millimetres per unit; 0 stays 0).
pub fn y16_to_metres(data: &[u8], scale_mm: f32) -> Vec<f32> {
    let to_m = scale_mm / 1000.0;
    data.chunks_exact(2).map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) * to_m).collect()
}

/// Which of a frame's timestamps marks it: the global (exposure) one when global timestamps are
/// on and fitted, else the host arrival time. Returns (host µs, is exposure). Zero means unset.
pub fn frame_stamp_us(m: &FrameMeta, global_enabled: bool) -> Result<(u64, bool), OrbbecError> {
    if global_enabled && m.global_us != 0 {
        return Ok((m.global_us, true));
    }
    if m.system_us == 0 {
        return Err(bad("frame has neither a global nor a system timestamp".into()));
    }
    Ok((m.system_us, false))
}

/// Microseconds to nanoseconds without overflow.
pub fn us_to_ns(us: u64) -> Result<u64, OrbbecError> {
    us.checked_mul(1000).ok_or_else(|| bad(format!("timestamp {us} us overflows nanoseconds")))
}

/// Everything a frameset must pass before it becomes a frame: colour and depth present, both
/// checked against `k`, and the stamp chosen. Returns (colour, depth, host stamp µs, is exposure,
/// device ns).
pub type CheckedFrameset = (Vec<u8>, Vec<f32>, u64, bool, u64);

pub fn check_frameset(
    set: &RawFrameset,
    k: &Intrinsics,
    global_enabled: bool,
) -> Result<CheckedFrameset, OrbbecError> {
    let color = set.color.as_ref().ok_or_else(|| bad("frameset without colour".into()))?;
    let depth = set.depth.as_ref().ok_or_else(|| bad("frameset without depth".into()))?;
    let rgb = color_rgb8(color, k)?;
    let metres = depth_metres(depth, k)?;
    let (stamp_us, exposure) = frame_stamp_us(&color.meta, global_enabled)?;
    us_to_ns(stamp_us)?;
    let device_ns = us_to_ns(color.meta.device_us)?;
    Ok((rgb, metres, stamp_us, exposure, device_ns))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn k(w: u32, h: u32) -> Intrinsics {
        Intrinsics {
            width: w,
            height: h,
            fx: 10.0,
            fy: 10.0,
            cx: 1.0,
            cy: 1.0,
            distortion: Default::default(),
        }
    }

    fn meta(w: u32, h: u32, format: i32) -> FrameMeta {
        FrameMeta {
            width: w,
            height: h,
            format,
            system_us: 5,
            depth_scale_mm: 1.0,
            ..Default::default()
        }
    }

    #[test]
    fn depth_units_become_metres() {
        let data = [0x00, 0x00, 0xE8, 0x03, 0x10, 0x27];
        assert_eq!(y16_to_metres(&data, 1.0), vec![0.0, 1.0, 10.0]);
        let tenth = y16_to_metres(&data, 0.1);
        assert!((tenth[1] - 0.1).abs() < 1e-6, "{tenth:?}");
    }

    #[test]
    fn a_good_frameset_passes_with_its_values() {
        let set = RawFrameset {
            color: Some(RawImage {
                meta: FrameMeta { device_us: 7, global_us: 9, ..meta(2, 1, FORMAT_RGB) },
                data: vec![1, 2, 3, 4, 5, 6],
            }),
            depth: Some(RawImage { meta: meta(2, 1, FORMAT_Z16), data: vec![0xE8, 0x03, 0, 0] }),
        };
        let (rgb, d, stamp, exposure, dev) = check_frameset(&set, &k(2, 1), true).expect("ok");
        assert_eq!(rgb, vec![1, 2, 3, 4, 5, 6]);
        assert_eq!(d, vec![1.0, 0.0]);
        assert_eq!((stamp, exposure, dev), (9, true, 7000));
        // Global timestamps off: the arrival time, and it says so.
        let (.., stamp, exposure, _) = check_frameset(&set, &k(2, 1), false).expect("ok");
        assert_eq!((stamp, exposure), (5, false));
    }

    #[test]
    fn the_sdk_s_lens_becomes_opencv_s_coefficients() {
        let k = [0.125, -0.25, 0.01, 0.5, 0.25, 0.125];
        let d = check_distortion(k, 0.001, -0.002, OB_DISTORTION_BROWN_CONRADY).expect("BC");
        assert_eq!(d.model, DistortionModel::BrownConrady);
        let (p1, p2, k3) = (f64::from(0.001f32), f64::from(-0.002f32), f64::from(0.01f32));
        assert_eq!(d.d(), &[0.125, -0.25, p1, p2, k3]);
        let d = check_distortion(k, 0.0, 0.0, OB_DISTORTION_BROWN_CONRADY_K6).expect("K6");
        assert_eq!(d.d(), &[0.125, -0.25, 0.0, 0.0, k3, 0.5, 0.25, 0.125]);
        assert!(check_distortion(k, 0.0, 0.0, OB_DISTORTION_NONE).expect("none").is_none());
        let e = check_distortion(k, 0.0, 0.0, 5).expect_err("Kannala-Brandt");
        assert!(e.message().contains("model 5"), "{e}");
        assert!(check_distortion([f32::NAN; 6], 0.0, 0.0, 3).is_err());
    }

    #[test]
    fn unaligned_depth_and_padded_colour_are_refused() {
        let c = RawImage { meta: meta(2, 1, FORMAT_RGB), data: vec![0; 6] };
        let d = RawImage { meta: meta(1, 1, FORMAT_Y16), data: vec![0; 2] };
        let e = depth_metres(&d, &k(2, 1)).expect_err("unaligned");
        assert!(e.message().contains("not aligned to colour 2x1"), "{e}");
        let padded = RawImage { data: vec![0; 8], ..c.clone() };
        assert!(color_rgb8(&padded, &k(2, 1)).is_err());
        assert!(color_rgb8(&c, &k(2, 1)).is_ok());
    }

    #[test]
    fn bad_intrinsics_are_refused() {
        assert!(check_intrinsics(f32::NAN, 1.0, 1.0, 1.0, 4, 4).is_err());
        assert!(check_intrinsics(1.0, 1.0, 9.0, 1.0, 4, 4).is_err());
        assert!(check_intrinsics(1.0, 1.0, 1.0, 1.0, 0, 4).is_err());
        let k = check_intrinsics(2.0, 3.0, 1.5, 2.5, 4, 4).expect("ok");
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (2.0, 3.0, 1.5, 2.5));
    }

    proptest! {
        /// Any metadata and bytes: a checked result or an error, never a panic; an accepted
        /// frameset has exactly one pixel per colour pixel, all depths finite and >= 0.
        #[test]
        fn any_frameset_is_checked_without_panic(
            cw in 0u32..70_000, ch in 0u32..70_000, dw in 0u32..70_000, dh in 0u32..70_000,
            cf in -2i32..40, df in -2i32..40, scale in proptest::num::f32::ANY,
            dev in any::<u64>(), sys in any::<u64>(), glob in any::<u64>(),
            clen in 0usize..64, dlen in 0usize..64, global in any::<bool>(),
            kw in 0u32..8, kh in 0u32..8,
        ) {
            let set = RawFrameset {
                color: Some(RawImage {
                    meta: FrameMeta { width: cw % 9, height: ch % 9, format: cf, device_us: dev,
                        system_us: sys, global_us: glob, depth_scale_mm: 0.0 },
                    data: vec![7; clen],
                }),
                depth: Some(RawImage {
                    meta: FrameMeta { width: dw % 9, height: dh % 9, format: df, device_us: dev,
                        system_us: sys, global_us: glob, depth_scale_mm: scale },
                    data: vec![0xFF; dlen],
                }),
            };
            let _ = image_bytes(cw, ch, 3);
            if let Ok((rgb, d, ..)) = check_frameset(&set, &k(kw, kh), global) {
                prop_assert_eq!(rgb.len(), (kw * kh * 3) as usize);
                prop_assert_eq!(d.len(), (kw * kh) as usize);
                prop_assert!(d.iter().all(|v| v.is_finite() && *v >= 0.0));
            }
        }

        /// Sizes near the limits never overflow: accepted sizes are exact products.
        #[test]
        fn image_sizes_are_exact_or_refused(w in any::<u32>(), h in any::<u32>(), b in 0u32..5) {
            match image_bytes(w, h, b) {
                Ok(n) => prop_assert_eq!(n as u128, u128::from(w) * u128::from(h) * u128::from(b)),
                Err(_) => prop_assert!(w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE),
            }
        }
    }
}
