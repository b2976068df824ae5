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
    // (tag index, the four corners as kornia orders them, OpenCV pixel convention).
    let mut raw: Vec<(usize, [(f64, f64); 4])> = Vec::new();
    for d in found {
        let Some(k) = board.index_of(u32::from(d.id)) else {
            out.foreign_tags += 1;
            continue;
        };
        if d.hamming > 1 || raw.iter().any(|(j, _)| *j == k) {
            continue;
        }
        // kornia's quad order is top-right, bottom-right, bottom-left, top-left; ours is top-left,
        // top-right, bottom-right, bottom-left. kornia's pixel (0, 0) covers [0, 1) x [0, 1);
        // OpenCV's is centred on (0, 0).
        let q = d.quad.corners;
        let px = |i: usize| (f64::from(q[i].x) - 0.5, f64::from(q[i].y) - 0.5);
        raw.push((k, [px(3), px(0), px(1), px(2)]));
    }
    // kornia names the corners by where they are in the image, so a tag turned by about 45 deg or
    // more comes back with its corners shifted by one or more places. The tags' centres do not
    // depend on that: a homography fitted to them says which image corner is which board corner.
    let h = if raw.len() >= 4 {
        let pairs: Vec<PointPair> = raw
            .iter()
            .map(|(k, c)| {
                let b = board.corners(*k);
                let bc = ((b[0].x + b[2].x) / 2.0, (b[0].y + b[2].y) / 2.0);
                let ic = (
                    c.iter().map(|p| p.0).sum::<f64>() / 4.0,
                    c.iter().map(|p| p.1).sum::<f64>() / 4.0,
                );
                (bc, ic)
            })
            .collect();
        homography(&pairs)
    } else {
        None
    };
    for (k, c) in raw {
        let pts = board.corners(k);
        let shift = h.map_or(0, |h| {
            (0..4)
                .min_by(|a, b| {
                    let err = |s: &usize| {
                        (0..4)
                            .map(|j| {
                                let (u, v) = apply(&h, pts[j].x, pts[j].y);
                                let p = c[(j + s) % 4];
                                (u - p.0).powi(2) + (v - p.1).powi(2)
                            })
                            .sum::<f64>()
                    };
                    err(a).total_cmp(&err(b))
                })
                .unwrap_or(0)
        });
        out.tags.push(board.id_of(k));
        for (j, p) in pts.iter().enumerate() {
            out.corners.push(Corner { board: *p, pixel: c[(j + shift) % 4] });
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

/// Homography (board x, y) -> image (u, v) from point pairs by the normalised direct linear
/// transform; `None` when degenerate.
/// A board point (x, y) and the pixel it was seen at.
type PointPair = ((f64, f64), (f64, f64));

fn homography(pairs: &[PointPair]) -> Option<nalgebra::Matrix3<f64>> {
    use nalgebra::{DMatrix, Matrix3};
    let n = pairs.len() as f64;
    let norm = |pts: Vec<(f64, f64)>| {
        let (mx, my) =
            (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
        let s =
            pts.iter().map(|p| ((p.0 - mx).powi(2) + (p.1 - my).powi(2)).sqrt()).sum::<f64>() / n;
        let s = if s > 1e-12 { std::f64::consts::SQRT_2 / s } else { 1.0 };
        Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
    };
    let tb = norm(pairs.iter().map(|p| p.0).collect());
    let ti = norm(pairs.iter().map(|p| p.1).collect());
    let mut a = DMatrix::<f64>::zeros(2 * pairs.len(), 9);
    for (i, (b, m)) in pairs.iter().enumerate() {
        let (x, y) = apply(&tb, b.0, b.1);
        let (u, v) = apply(&ti, m.0, m.1);
        let h = [x, y, 1.0];
        for j in 0..3 {
            a[(2 * i, j)] = h[j];
            a[(2 * i, 6 + j)] = -u * h[j];
            a[(2 * i + 1, 3 + j)] = h[j];
            a[(2 * i + 1, 6 + j)] = -v * h[j];
        }
    }
    let eig = (a.transpose() * &a).symmetric_eigen();
    let v = eig.eigenvectors.column(eig.eigenvalues.imin());
    let hn = Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
    let h = ti.try_inverse()? * hn * tb;
    h.iter().all(|x| x.is_finite()).then_some(h)
}

fn apply(h: &nalgebra::Matrix3<f64>, x: f64, y: f64) -> (f64, f64) {
    let p = h * nalgebra::Vector3::new(x, y, 1.0);
    (p.x / p.z, p.y / p.z)
}
