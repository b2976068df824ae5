//! Tests against the REAL Orbbec SDK library (`.deps/lib/libOrbbecSDK.so` from `make setup`), no
//! camera needed: frames built with the SDK's own frame API (video stream profiles with
//! intrinsics, distortion and extrinsics, video frames, a frameset) go through the driver's
//! `Align` filter and copy-out ([`super::sdk::align_and_copy`]) and its checked conversion
//! ([`super::frame::check_frameset`]), and must come out aligned to colour, in metres.

use std::path::PathBuf;
use std::sync::Arc;

use super::ffi::{
    AlignFilter, Frame, ObCameraIntrinsic, ObExtrinsic, ObMultiDeviceSyncConfig, Profile,
    ProfileDesc, Sdk, OB_FRAME_COLOR, OB_FRAME_DEPTH, OB_STREAM_COLOR, OB_STREAM_DEPTH,
};
use super::frame::{check_frameset, check_intrinsics, FORMAT_RGB, FORMAT_Y16};
use super::sdk::align_and_copy;

const CW: u32 = 64;
const CH: u32 = 48;
const DW: u32 = 32;
const DH: u32 = 24;

fn sdk() -> Arc<Sdk> {
    let p = PathBuf::from(env!("HITL_DEPS_LIB")).join("libOrbbecSDK.so");
    assert!(p.exists(), "{} is missing: run make setup", p.display());
    let sdk = Sdk::load(&p).expect("load libOrbbecSDK");
    let _ = sdk.quiet_logs();
    sdk
}

/// Depth units of 0.1 mm, `w` wide: the given pixels at the given units, nothing elsewhere.
fn depth_image(w: u32, h: u32, marks: &[(u32, u32, u16)]) -> Vec<u8> {
    let mut d = vec![0u8; (w * h * 2) as usize];
    for &(u, v, units) in marks {
        let i = ((v * w + u) * 2) as usize;
        d[i..i + 2].copy_from_slice(&units.to_le_bytes());
    }
    d
}

fn color_image() -> Vec<u8> {
    (0..CW * CH * 3).map(|i| (i % 251) as u8).collect()
}

/// Colour 64x48 (f 50 px), depth 32x24 (f 25 px) with depth pixel (16, 12) at 1 m and (8, 6) at
/// 2 m, depth -> colour translated by `tx_mm` along x; returns the converted colour and depth
/// (metres), stamp, whether it is an exposure stamp and the device time.
fn align(tx_mm: f32) -> (Vec<u8>, Vec<f32>, u64, bool, u64) {
    let dk = ObCameraIntrinsic { fx: 25.0, fy: 25.0, cx: 16.0, cy: 12.0, width: 32, height: 24 };
    let depth = depth_image(DW, DH, &[(16, 12, 10_000), (8, 6, 20_000)]);
    align_depth(dk, &depth, tx_mm)
}

fn align_depth(
    dk: ObCameraIntrinsic,
    depth: &[u8],
    tx_mm: f32,
) -> (Vec<u8>, Vec<f32>, u64, bool, u64) {
    let sdk = sdk();
    let cd = ProfileDesc { width: CW, height: CH, format: FORMAT_RGB, fps: 30 };
    let dd = ProfileDesc {
        width: u32::try_from(dk.width).expect("width"),
        height: u32::try_from(dk.height).expect("height"),
        format: FORMAT_Y16,
        fps: 30,
    };
    let ck = ObCameraIntrinsic { fx: 50.0, fy: 50.0, cx: 32.0, cy: 24.0, width: 64, height: 48 };
    let cp = Profile::new_video(&sdk, OB_STREAM_COLOR, cd, ck).expect("colour profile");
    let dp = Profile::new_video(&sdk, OB_STREAM_DEPTH, dd, dk).expect("depth profile");
    let rot = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    dp.set_extrinsic_to(&cp, ObExtrinsic { rot, trans: [tx_mm, 0.0, 0.0] }).expect("extrinsic");
    let color = color_image();
    let cf = Frame::new_video(&cp, OB_FRAME_COLOR, cd, &color, 1_000, 2_000, None).expect("colour");
    let df =
        Frame::new_video(&dp, OB_FRAME_DEPTH, dd, depth, 1_000, 2_000, Some(0.1)).expect("depth");
    let set = Frame::new_frameset(&sdk, &[&cf, &df]).expect("frameset");
    let mut filter = AlignFilter::depth_to_color(&sdk, false).expect("Align filter");
    let raw = align_and_copy(&mut filter, &set).expect("aligned");
    let k = check_intrinsics(50.0, 50.0, 32.0, 24.0, CW, CH).expect("intrinsics");
    check_frameset(&raw, &k, true).expect("the aligned frameset passes the driver's checks")
}

/// Mean (u, v) of the pixels whose depth is within 1 cm of `metres`, and how many there are.
fn centroid(depth: &[f32], metres: f32) -> (f64, f64, usize) {
    let (mut su, mut sv, mut n) = (0.0, 0.0, 0usize);
    for (i, d) in depth.iter().enumerate() {
        if (d - metres).abs() < 0.01 {
            su += (i % CW as usize) as f64;
            sv += (i / CW as usize) as f64;
            n += 1;
        }
    }
    (su / n.max(1) as f64, sv / n.max(1) as f64, n)
}

#[test]
fn depth_lands_where_the_extrinsics_say_in_metres_at_colour_size() {
    let (rgb, depth, stamp_us, exposure, device_ns) = align(40.0);
    assert_eq!(rgb, color_image(), "colour passes through unchanged");
    assert_eq!(depth.len(), (CW * CH) as usize, "depth at the colour size");
    // 1 m at depth pixel (16, 12): x = 0 -> colour x = 40 mm -> u = 50 * 0.04 + 32 = 34, v = 24.
    // (The SDK fills the 2x2 colour pixels the depth pixel covers: centroid (34.5, 24.5) with
    // 2.9.3; without the baseline it would be 2 px to the left, see the next test.)
    let (u, v, n) = centroid(&depth, 1.0);
    assert!(n > 0, "the 1 m pixel is somewhere in the aligned depth");
    assert!((u - 34.0).abs() <= 0.75 && (v - 24.0).abs() <= 0.75, "1 m at ({u}, {v}), n {n}");
    // 2 m at depth pixel (8, 6): x = -640 mm -> -600 mm -> u = 17; y = -480 mm -> v = 12.
    let (u, v, n) = centroid(&depth, 2.0);
    assert!(n > 0, "the 2 m pixel is somewhere in the aligned depth");
    assert!((u - 17.0).abs() <= 0.75 && (v - 12.0).abs() <= 0.75, "2 m at ({u}, {v}), n {n}");
    let elsewhere = depth
        .iter()
        .filter(|d| **d != 0.0 && (**d - 1.0).abs() > 0.01 && (**d - 2.0).abs() > 0.01)
        .count();
    assert_eq!(elsewhere, 0, "no other depth values appear");
    // No global timestamp on a built frame: the arrival (system) time, and it says so.
    assert_eq!((stamp_us, exposure, device_ns), (2_000, false, 1_000_000));
}

#[test]
fn without_a_baseline_the_same_pixel_lands_on_the_principal_point() {
    let (_, depth, ..) = align(0.0);
    let (u, v, n) = centroid(&depth, 1.0);
    assert!(n > 0);
    assert!((u - 32.0).abs() <= 0.75 && (v - 24.0).abs() <= 0.75, "1 m at ({u}, {v})");
}

/// The other case: depth and colour of the same size and intrinsics are still two
/// cameras a baseline apart; the depth must move, not just be relabelled.
#[test]
fn equal_sizes_are_aligned_too() {
    let dk = ObCameraIntrinsic { fx: 50.0, fy: 50.0, cx: 32.0, cy: 24.0, width: 64, height: 48 };
    let depth = depth_image(CW, CH, &[(32, 24, 10_000)]);
    let (_, aligned, ..) = align_depth(dk, &depth, 40.0);
    let (u, v, n) = centroid(&aligned, 1.0);
    assert!(n > 0);
    assert_eq!(aligned[24 * CW as usize + 32], 0.0, "the unaligned place is empty");
    assert!((u - 34.0).abs() <= 0.75 && (v - 24.0).abs() <= 0.75, "1 m at ({u}, {v}), n {n}");
}

/// The sync config struct is packed in the header (25 bytes); a padded layout would shift
/// `triggerOutDelayUs` and `framesPerTrigger`.
#[test]
fn the_sync_config_layout_matches_the_packed_header() {
    assert_eq!(std::mem::size_of::<ObMultiDeviceSyncConfig>(), 25);
    assert_eq!(std::mem::size_of::<ObCameraIntrinsic>(), 20);
    assert_eq!(std::mem::size_of::<ObExtrinsic>(), 48);
}
