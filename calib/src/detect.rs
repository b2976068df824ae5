//! Board detection: the AprilTag C library finds and decodes the tags (no detection is written
//! here); this module keeps the board's own tags and pairs each detected corner with its board
//! point.

use crate::board::Board;
use apriltag::{Detector, Family, Image};
use nalgebra::Point3;

/// One detected board corner: where it is on the board and where it was seen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    pub board: Point3<f64>,
    pub pixel: (f64, f64),
}

/// The board as seen in one image.
#[derive(Debug, Clone, Default)]
pub struct Detection {
    /// Ids of this board's tags that were decoded.
    pub tags: Vec<u32>,
    /// Their corners (four per tag).
    pub corners: Vec<Corner>,
    /// Decoded tags that are not on this board (another board or a stray code).
    pub foreign_tags: usize,
}

/// Why an image could not be searched.
#[derive(Debug, thiserror::Error)]
#[error("tag detection: {0}")]
pub struct DetectError(String);

/// Detect `board` in an 8-bit grey image (`width` x `height`, row-major).
pub fn detect(
    board: &Board,
    width: usize,
    height: usize,
    grey: &[u8],
) -> Result<Detection, DetectError> {
    if grey.len() != width * height {
        return Err(DetectError(format!("{} bytes for a {width}x{height} image", grey.len())));
    }
    if width == 0 || height == 0 {
        return Err(DetectError(format!("empty {width}x{height} image")));
    }
    let mut image =
        Image::zeros_with_stride(width, height, width).map_err(|e| DetectError(e.to_string()))?;
    let stride = image.stride();
    for (dst, src) in image.as_slice_mut().chunks_exact_mut(stride).zip(grey.chunks_exact(width)) {
        dst[..width].copy_from_slice(src);
    }
    // Hamming distance up to 1 is corrected (as before); full resolution: the board's cells are
    // a few pixels wide in a small simulated image.
    let mut detector = Detector::builder()
        .add_family_bits(Family::tag_36h11(), 1)
        .build()
        .map_err(|e| DetectError(e.to_string()))?;
    detector.set_decimation(1.0);
    let mut out = Detection::default();
    let mut seen = Vec::new();
    for d in detector.detect(&image) {
        let Some(k) = u32::try_from(d.id()).ok().and_then(|id| board.index_of(id)) else {
            out.foreign_tags += 1;
            continue;
        };
        if d.hamming() > 1 || seen.contains(&k) {
            continue;
        }
        seen.push(k);
        // The library names the corners in the tag's own frame, its decoded rotation applied:
        // (-1, 1), (1, 1), (1, -1), (-1, -1) with y down the printed tag, that is bottom-left,
        // bottom-right, top-right, top-left; ours run top-left, top-right, bottom-right,
        // bottom-left. Its pixel (0, 0) covers [0, 1) x [0, 1); OpenCV's is centred on (0, 0).
        let p = d.corners();
        let px = |i: usize| (p[i][0] - 0.5, p[i][1] - 0.5);
        let pixels = [px(3), px(2), px(1), px(0)];
        out.tags.push(board.id_of(k));
        for (b, pixel) in board.corners(k).iter().zip(pixels) {
            out.corners.push(Corner { board: *b, pixel });
        }
    }
    Ok(out)
}

/// Grey from packed RGB8 (ITU-R BT.601 weights).
pub fn rgb_to_grey(rgb: &[u8]) -> Vec<u8> {
    rgb.chunks_exact(3)
        .map(|p| {
            let y = 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]);
            y.round().clamp(0.0, 255.0) as u8
        })
        .collect()
}
