//! Orbbec frame metadata and bytes as the SDK could hand them over (sizes, formats, depth scale,
//! timestamps, data of any length): the driver's checks must answer every input with a frame or
//! an error, never a panic, and an accepted frame must fit the colour intrinsics exactly.
#![no_main]

use hitl_drivers::orbbec::frame::{check_frameset, check_intrinsics};
use hitl_drivers::orbbec::{FrameMeta, RawFrameset, RawImage};
use libfuzzer_sys::fuzz_target;

fn take<const N: usize>(data: &mut &[u8]) -> [u8; N] {
    let mut out = [0u8; N];
    let n = N.min(data.len());
    out[..n].copy_from_slice(&data[..n]);
    *data = &data[n..];
    out
}

fn meta(data: &mut &[u8]) -> FrameMeta {
    FrameMeta {
        width: u32::from_le_bytes(take(data)) % 64,
        height: u32::from_le_bytes(take(data)) % 64,
        format: i32::from_le_bytes(take(data)),
        device_us: u64::from_le_bytes(take(data)),
        system_us: u64::from_le_bytes(take(data)),
        global_us: u64::from_le_bytes(take(data)),
        depth_scale_mm: f32::from_le_bytes(take(data)),
    }
}

fuzz_target!(|input: &[u8]| {
    let mut data = input;
    let [kw, kh, global, split] = take::<4>(&mut data);
    let k = [f32::from_le_bytes(take(&mut data)), f32::from_le_bytes(take(&mut data))];
    let color_meta = meta(&mut data);
    let depth_meta = meta(&mut data);
    let cut = usize::from(split).min(data.len()) * data.len() / 256;
    let (c, d) = data.split_at(cut.min(data.len()));
    let set = RawFrameset {
        color: Some(RawImage { meta: color_meta, data: c.to_vec() }),
        depth: Some(RawImage { meta: depth_meta, data: d.to_vec() }),
    };
    let (w, h) = (u32::from(kw % 16), u32::from(kh % 16));
    let Ok(intrinsics) = check_intrinsics(k[0], k[0], k[1], k[1], w, h) else { return };
    if let Ok((rgb, depth, ..)) = check_frameset(&set, &intrinsics, global & 1 == 1) {
        assert_eq!(rgb.len(), (w * h * 3) as usize);
        assert_eq!(depth.len(), (w * h) as usize);
        assert!(depth.iter().all(|v| v.is_finite() && *v >= 0.0));
    }
});
