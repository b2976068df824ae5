//! Board detection: kornia-apriltag finds and decodes the tags (no detection is written here);
//! this module keeps the board's own tags and pairs each detected corner with its board point.

use crate::board::Board;
use kornia_apriltag::family::TagFamilyKind;
use kornia_apriltag::{AprilTagDecoder, DecodeTagsConfig};
use kornia_image::{Image, ImageSize};
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
    let size = ImageSize { width, height };
    let mut config = DecodeTagsConfig::new(vec![TagFamilyKind::Tag36H11])
        .map_err(|e| DetectError(e.to_string()))?;
    // Full resolution: the board's cells are a few pixels wide in a small simulated image.
    config.downscale_factor = 1;
    config.min_tag_width = 3;
    let mut decoder = AprilTagDecoder::new(config, size).map_err(|e| DetectError(e.to_string()))?;
    let image = Image::<u8, 1>::new(size, grey.to_vec()).map_err(|e| DetectError(e.to_string()))?;
    let found = decoder.decode(&image).map_err(|e| DetectError(e.to_string()))?;
    let mut out = Detection::default();
    for d in found {
        let Some(k) = board.index_of(u32::from(d.id)) else {
            out.foreign_tags += 1;
            continue;
        };
        if d.hamming > 1 || out.tags.contains(&u32::from(d.id)) {
            continue;
        }
        // kornia's quad order is top-right, bottom-right, bottom-left, top-left of the tag as
        // drawn; ours is top-left, top-right, bottom-right, bottom-left.
        let q = d.quad.corners;
        let seen = [q[3], q[0], q[1], q[2]];
        let pts = board.corners(k);
        out.tags.push(u32::from(d.id));
        // kornia's pixel (0, 0) covers [0, 1) x [0, 1); OpenCV's is centred on (0, 0).
        for (p, s) in pts.iter().zip(seen) {
            let pixel = (f64::from(s.x) - 0.5, f64::from(s.y) - 0.5);
            out.corners.push(Corner { board: *p, pixel });
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
