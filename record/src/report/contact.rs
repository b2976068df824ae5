//! The report's contact sheet: a few captures, evenly spread over the run, with the target's
//! ground-truth and estimated silhouettes outlined over the camera image (the paper's overlay
//! figure).
//!
//! Ground truth is the recorded `/camera/mask` when the run recorded one, else the target model
//! projected at `/pose/gt`; the estimate is the target model projected at `/pose/estimate`. This
//! crate does not know the perception crate's target models: the caller hands in a
//! [`ModelSource`] that turns the run's metadata into a [`TargetMesh`] (lab metres, in the
//! target's frame, scaled as the run scaled it). Frames wider than
//! [`ContactOptions::max_width`] are shrunk with a box filter, and the silhouettes are rasterised
//! at the shrunk size with the intrinsics scaled to it, so an outline is one sheet pixel wide.
//!
//! Pixel convention (the simulated camera's and the tracker's): pixel `(x, y)` is centred on
//! image coordinate `(x, y)`, and a pixel belongs to a silhouette when its centre lies in a
//! projected triangle.

use super::summary::{secs, t0};
use super::ReportError;
use crate::reader::{decode_image, decode_intrinsics, depth_metres, packed_rows, visit, Recording};
use crate::topics;
use foxglove::messages as fg;
use hitl_hal::Intrinsics;
use hitl_hal::{pose, Pose};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// Outline colour of the ground-truth silhouette (rgb8).
pub const GROUND_TRUTH_COLOUR: [u8; 3] = [0, 255, 0];
/// Outline colour of the estimated silhouette (rgb8); drawn over the ground truth's.
pub const ESTIMATE_COLOUR: [u8; 3] = [255, 0, 255];
/// Sub-folder of the report that holds the sheet's PNGs.
pub const CONTACT_DIR: &str = "contact";
/// Triangles with a vertex closer to the camera than this (metres, along its axis) are not drawn.
const NEAR_M: f64 = 1e-3;

/// A target's triangle mesh in its own frame, lab metres (as the run scaled it).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TargetMesh {
    pub vertices: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
}

/// Turns the run's `run` metadata record (empty when it has none) into the target's mesh, or
/// says why it cannot.
pub type ModelSource<'a> = &'a dyn Fn(&BTreeMap<String, String>) -> Result<TargetMesh, String>;

/// What the sheet shows.
#[derive(Clone, Copy)]
pub struct ContactOptions<'a> {
    /// Captures on the sheet (evenly spread over the recorded ones, first and last included).
    pub frames: usize,
    /// Frames wider than this many pixels are shrunk to it.
    pub max_width: u32,
    /// The target model, for the estimated silhouette (and the ground truth without a mask).
    pub model: Option<ModelSource<'a>>,
    /// Show each frame cropped around the target (its ground-truth mask's box, grown this many
    /// times, at the frame's aspect ratio) instead of whole: at a fly-around's range a wide
    /// camera shows the target a few dozen pixels wide. `None`: whole frames.
    pub zoom: Option<f64>,
}

impl Default for ContactOptions<'_> {
    fn default() -> Self {
        ContactOptions { frames: 8, max_width: 480, model: None, zoom: None }
    }
}

/// Where a frame's ground-truth silhouette came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GroundTruthSource {
    /// The recorded `/camera/mask`.
    Mask,
    /// The target model projected at the `/pose/gt` pose.
    Model,
}

/// One capture on the sheet.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ContactFrame {
    /// Index among the recorded captures (0-based, capture order).
    pub capture: usize,
    pub capture_ns: u64,
    /// Seconds from the run's start.
    pub t_s: f64,
    /// The PNG, relative to the report folder.
    pub file: String,
    pub width: u32,
    pub height: u32,
    pub ground_truth: Option<GroundTruthSource>,
    /// An estimated silhouette is drawn.
    pub estimate: bool,
    /// Translation error of the recorded estimate, lab millimetres.
    pub et_lab_mm: Option<f64>,
    /// The same in real metres (lab / the run's scale), when the run recorded its scale.
    pub et_m: Option<f64>,
    /// Rotation error of the recorded estimate, degrees, as recorded (`hitl eval` calibrates
    /// rotation on the first frame, as the paper does; this does not).
    pub er_deg: Option<f64>,
    /// Intersection over union of the estimated and ground-truth silhouettes (sheet pixels).
    pub estimate_iou: Option<f64>,
    /// Intersection over union of the model at the ground-truth pose and the recorded mask: how
    /// well model, scale and intrinsics explain the images (parts hidden by the stand lower it).
    pub model_mask_iou: Option<f64>,
}

/// The sheet as written (the `contact_sheet` of summary.json).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ContactSheet {
    /// Captures the recording holds.
    pub captures: usize,
    pub frames: Vec<ContactFrame>,
    /// Why something is missing (no camera frames, no model, an unreadable image).
    pub notes: Vec<String>,
}

/// A binary image: which pixels belong to the target.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Silhouette {
    pub width: u32,
    pub height: u32,
    /// Row-major.
    pub inside: Vec<bool>,
}

impl Silhouette {
    pub fn empty(width: u32, height: u32) -> Silhouette {
        Silhouette { width, height, inside: vec![false; width as usize * height as usize] }
    }

    /// From a mono8 mask (non-zero: target).
    pub fn from_mono8(width: u32, height: u32, data: &[u8]) -> Option<Silhouette> {
        (data.len() == width as usize * height as usize).then(|| Silhouette {
            width,
            height,
            inside: data.iter().map(|&v| v != 0).collect(),
        })
    }

    pub fn get(&self, x: u32, y: u32) -> bool {
        x < self.width && y < self.height && self.inside[(y * self.width + x) as usize]
    }

    pub fn area(&self) -> usize {
        self.inside.iter().filter(|&&v| v).count()
    }

    /// The outline: pixels of the silhouette with a 4-neighbour (inside the image) that is not.
    /// A silhouette cut by the image border is not outlined along it.
    pub fn outline(&self) -> Silhouette {
        let (w, h) = (self.width, self.height);
        let mut out = Silhouette::empty(w, h);
        for y in 0..h {
            for x in 0..w {
                if !self.get(x, y) {
                    continue;
                }
                let off = |dx: i64, dy: i64| {
                    let (nx, ny) = (i64::from(x) + dx, i64::from(y) + dy);
                    nx >= 0
                        && ny >= 0
                        && nx < i64::from(w)
                        && ny < i64::from(h)
                        && !self.get(nx as u32, ny as u32)
                };
                if off(-1, 0) || off(1, 0) || off(0, -1) || off(0, 1) {
                    out.inside[(y * w + x) as usize] = true;
                }
            }
        }
        out
    }

    /// Intersection over union (`None` when sizes differ or both are empty).
    pub fn iou(&self, other: &Silhouette) -> Option<f64> {
        if (self.width, self.height) != (other.width, other.height) {
            return None;
        }
        let (mut i, mut u) = (0usize, 0usize);
        for (a, b) in self.inside.iter().zip(&other.inside) {
            i += usize::from(*a && *b);
            u += usize::from(*a || *b);
        }
        (u > 0).then(|| i as f64 / u as f64)
    }
}

/// The target's silhouette: `mesh` placed at `camera_T_target` = `pose` (OpenCV camera axes),
/// projected through `k` (its lens distortion included: vertices are placed where the lens
/// puts them, edges drawn straight between them) and filled triangle by triangle (scanlines through pixel
/// centres). Triangles reaching behind the camera's near plane are left out.
pub fn rasterize(mesh: &TargetMesh, pose: &Pose, k: &Intrinsics) -> Silhouette {
    let mut s = Silhouette::empty(k.width, k.height);
    let projected: Vec<Option<[f64; 2]>> = mesh
        .vertices
        .iter()
        .map(|v| {
            let p = pose.transform_point(&nalgebra::Point3::from(*v));
            let (u, w) = k.project(p.x, p.y, p.z);
            (p.z > NEAR_M && u.is_finite() && w.is_finite()).then_some([u, w])
        })
        .collect();
    for f in &mesh.faces {
        let corner = |i: u32| projected.get(i as usize).copied().flatten();
        if let (Some(a), Some(b), Some(c)) = (corner(f[0]), corner(f[1]), corner(f[2])) {
            fill_triangle(&mut s, [a, b, c]);
        }
    }
    s
}

/// Sets the pixels whose centres lie in the triangle (edges included).
fn fill_triangle(s: &mut Silhouette, t: [[f64; 2]; 3]) {
    if s.width == 0 || s.height == 0 {
        return;
    }
    let vmin = t.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
    let vmax = t.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    let y0 = vmin.ceil().max(0.0);
    let y1 = vmax.floor().min(f64::from(s.height - 1));
    if y0 > y1 {
        return;
    }
    for y in y0 as u32..=y1 as u32 {
        let yf = f64::from(y);
        let (mut xl, mut xr) = (f64::INFINITY, f64::NEG_INFINITY);
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (lo, hi) = if a[1] <= b[1] { (a, b) } else { (b, a) };
            if yf < lo[1] || yf > hi[1] {
                continue;
            }
            let xs = if hi[1] > lo[1] {
                let x = lo[0] + (yf - lo[1]) * (hi[0] - lo[0]) / (hi[1] - lo[1]);
                [x, x]
            } else {
                // A horizontal edge on this row: both its ends.
                [lo[0], hi[0]]
            };
            for x in xs {
                xl = xl.min(x);
                xr = xr.max(x);
            }
        }
        let x0 = xl.ceil().max(0.0);
        let x1 = xr.floor().min(f64::from(s.width - 1));
        if x0 > x1 {
            continue;
        }
        let row = (y * s.width) as usize;
        s.inside[row + x0 as usize..=row + x1 as usize].fill(true);
    }
}

/// The sheet's size for a `width` x `height` frame: shrunk to `max_width` wide, aspect kept.
pub fn sheet_size(width: u32, height: u32, max_width: u32) -> (u32, u32) {
    if width <= max_width || width == 0 {
        return (width, height);
    }
    let h = (u64::from(height) * u64::from(max_width) + u64::from(width) / 2) / u64::from(width);
    (max_width.max(1), (h as u32).max(1))
}

/// Output bin of each source index: `floor((i + 0.5) * to / from)`.
fn bins(from: u32, to: u32) -> Vec<usize> {
    (0..u64::from(from))
        .map(|i| (((2 * i + 1) * u64::from(to)) / (2 * u64::from(from))) as usize)
        .map(|b| b.min(to.saturating_sub(1) as usize))
        .collect()
}

/// Box-filter `channels`-channel u8 pixels from `w` x `h` to `ow` x `oh` (`ow <= w`, `oh <= h`).
fn shrink_u8(src: &[u8], channels: usize, (w, h): (u32, u32), (ow, oh): (u32, u32)) -> Vec<u8> {
    if (ow, oh) == (w, h) {
        return src.to_vec();
    }
    let (bx, by) = (bins(w, ow), bins(h, oh));
    let mut sum = vec![0u32; ow as usize * oh as usize * channels];
    let mut count = vec![0u32; ow as usize * oh as usize];
    for (y, oy) in by.iter().enumerate() {
        for (x, ox) in bx.iter().enumerate() {
            let o = oy * ow as usize + ox;
            count[o] += 1;
            let s = (y * w as usize + x) * channels;
            for c in 0..channels {
                sum[o * channels + c] += u32::from(src[s + c]);
            }
        }
    }
    sum.iter()
        .enumerate()
        .map(|(i, v)| {
            let n = count[i / channels].max(1);
            ((v + n / 2) / n) as u8
        })
        .collect()
}

/// Resize `channels`-channel u8 pixels from `w` x `h` to `ow` x `oh`: the box filter when
/// shrinking, else each output pixel takes the source pixel its centre falls in (a zoomed crop
/// enlarged to the sheet's width shows its pixels as blocks, not smoothed).
fn resize_u8(src: &[u8], channels: usize, (w, h): (u32, u32), (ow, oh): (u32, u32)) -> Vec<u8> {
    if ow <= w && oh <= h {
        return shrink_u8(src, channels, (w, h), (ow, oh));
    }
    let at = |o: u32, from: u32, to: u32| {
        (((2 * u64::from(o) + 1) * u64::from(from)) / (2 * u64::from(to))).min(u64::from(from) - 1)
            as usize
    };
    let mut out = Vec::with_capacity(ow as usize * oh as usize * channels);
    for y in 0..oh {
        let sy = at(y, h, oh);
        for x in 0..ow {
            let s = (sy * w as usize + at(x, w, ow)) * channels;
            out.extend_from_slice(&src[s..s + channels]);
        }
    }
    out
}

/// Resize a silhouette as [`resize_u8`] does (shrunk: inside when at least half its source
/// pixels are).
fn resize_silhouette(s: &Silhouette, ow: u32, oh: u32) -> Silhouette {
    let bytes: Vec<u8> = s.inside.iter().map(|&v| if v { 255 } else { 0 }).collect();
    let out = resize_u8(&bytes, 1, (s.width, s.height), (ow, oh));
    Silhouette { width: ow, height: oh, inside: out.iter().map(|&v| v >= 128).collect() }
}

/// rgb8 pixels of a colour image (rgb8, bgr8 or mono8).
fn rgb_of(img: &fg::RawImage) -> Option<Vec<u8>> {
    match img.encoding.as_str() {
        "rgb8" => packed_rows(img, 3),
        "bgr8" => {
            Some(packed_rows(img, 3)?.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect())
        }
        "mono8" => Some(packed_rows(img, 1)?.iter().flat_map(|&v| [v, v, v]).collect()),
        _ => None,
    }
}

/// A depth image as grey rgb8: near is bright, no return is black.
fn depth_grey(img: &fg::RawImage) -> Option<Vec<u8>> {
    let d = depth_metres(img)?;
    let valid = d.iter().copied().filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = valid.fold((f32::INFINITY, 0.0f32), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let span = (hi - lo).max(1e-6);
    Some(
        d.iter()
            .flat_map(|&v| {
                let g =
                    if v.is_finite() && v > 0.0 { 255.0 - 200.0 * (v - lo) / span } else { 0.0 };
                [g as u8; 3]
            })
            .collect(),
    )
}

fn paint(rgb: &mut [u8], s: &Silhouette, colour: [u8; 3]) {
    for (i, _) in s.inside.iter().enumerate().filter(|(_, v)| **v) {
        rgb[i * 3..i * 3 + 3].copy_from_slice(&colour);
    }
}

fn write_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), std::io::Error> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut enc = png::Encoder::new(file, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(std::io::Error::other)?;
    writer.write_image_data(rgb).map_err(std::io::Error::other)?;
    writer.finish().map_err(std::io::Error::other)
}

/// The pose of capture `t` in a list sorted by capture time.
fn pose_at(list: &[crate::msg::PoseStamped], t: u64) -> Option<Pose> {
    let i = list.partition_point(|p| p.capture_ns < t);
    list.get(i).filter(|p| p.capture_ns == t).map(|p| p.pose)
}

/// Indices of `n` of `total` items, evenly spread, first and last included.
fn spread(total: usize, n: usize) -> Vec<usize> {
    let n = n.min(total);
    match n {
        0 => Vec::new(),
        1 => vec![0],
        _ => (0..n).map(|k| k * (total - 1) / (n - 1)).collect(),
    }
}

#[derive(Default)]
struct Pixels {
    color: Option<fg::RawImage>,
    depth: Option<fg::RawImage>,
    mask: Option<fg::RawImage>,
}

/// Write the sheet's PNGs into `dir/contact/` (removing PNGs a previous report left there) and
/// say what is on it. `rec` is `mcap` as [`crate::reader::read_recording`] read it.
pub fn write_contact_sheet(
    mcap: &Path,
    rec: &Recording,
    dir: &Path,
    opts: &ContactOptions<'_>,
) -> Result<(ContactSheet, Vec<PathBuf>), ReportError> {
    let mut sheet = ContactSheet::default();
    let captures = read_captures(mcap, &mut sheet)?;
    if captures.is_empty() {
        sheet.notes.push(
            "this recording holds no camera frames (a run without a camera, or one stopped before \
             its first capture): no contact sheet"
                .to_string(),
        );
        return Ok((sheet, Vec::new()));
    }
    let chosen = spread(captures.len(), opts.frames);
    let mut pixels = read_pixels(mcap, &captures, &chosen, &mut sheet)?;

    let empty = BTreeMap::new();
    let run = rec.metadata.get(topics::META_RUN).unwrap_or(&empty);
    let model = match opts.model {
        Some(source) => match source(run) {
            Ok(m) => Some(m),
            Err(e) => {
                sheet.notes.push(format!("no model silhouettes (target model: {e})"));
                None
            }
        },
        None => {
            sheet.notes.push("no target model given: no model silhouettes".to_string());
            None
        }
    };
    let out_dir = dir.join(CONTACT_DIR);
    std::fs::create_dir_all(&out_dir).map_err(super::io(&out_dir))?;
    clear_old_pngs(&out_dir)?;
    let ctx = Sheet {
        rec,
        opts,
        model,
        scale: run.get("scale").and_then(|s| s.parse::<f64>().ok()).filter(|s| *s > 0.0),
        origin: match t0(rec) {
            0 => captures[0].0,
            t => t,
        },
        out_dir,
    };
    let mut files = Vec::new();
    for &i in &chosen {
        let (t, k) = captures[i];
        let px = pixels.remove(&t).unwrap_or_default();
        let (frame, path) = ctx.draw(i, t, k, px)?;
        files.push(path);
        sheet.frames.push(frame);
    }
    Ok((sheet, files))
}

/// The captures (stamp, intrinsics) in time order, from the per-frame calibration.
fn read_captures(
    mcap: &Path,
    sheet: &mut ContactSheet,
) -> Result<Vec<(u64, Intrinsics)>, ReportError> {
    let mut captures: Vec<(u64, Intrinsics)> = Vec::new();
    let mut bad_calibration = 0usize;
    visit(
        mcap,
        |m| {
            if m.topic == topics::CALIBRATION {
                match decode_intrinsics(m.data, m.log_time) {
                    Ok((_, k)) => captures.push((m.log_time, k)),
                    Err(_) => bad_calibration += 1,
                }
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )?;
    captures.sort_by_key(|c| c.0);
    captures.dedup_by_key(|c| c.0);
    sheet.captures = captures.len();
    if bad_calibration > 0 {
        sheet.notes.push(format!("{bad_calibration} unreadable /camera/calibration messages"));
    }
    Ok(captures)
}

/// The images of the `chosen` captures only, by capture stamp.
fn read_pixels(
    mcap: &Path,
    captures: &[(u64, Intrinsics)],
    chosen: &[usize],
    sheet: &mut ContactSheet,
) -> Result<HashMap<u64, Pixels>, ReportError> {
    let mut pixels: HashMap<u64, Pixels> =
        chosen.iter().map(|&i| (captures[i].0, Pixels::default())).collect();
    let mut bad_images = 0usize;
    visit(
        mcap,
        |m| {
            let slot = match m.topic {
                topics::COLOR | topics::DEPTH | topics::MASK => pixels.get_mut(&m.log_time),
                _ => None,
            };
            if let Some(p) = slot {
                match decode_image(m.data) {
                    Ok(img) => match m.topic {
                        topics::COLOR => p.color = Some(img),
                        topics::DEPTH => p.depth = Some(img),
                        _ => p.mask = Some(img),
                    },
                    Err(_) => bad_images += 1,
                }
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )?;
    if bad_images > 0 {
        sheet.notes.push(format!("{bad_images} images of the sheet's captures could not be read"));
    }
    Ok(pixels)
}

/// What every tile of a sheet shares.
struct Sheet<'a> {
    rec: &'a Recording,
    opts: &'a ContactOptions<'a>,
    model: Option<TargetMesh>,
    /// The run's scale (lab m per real m), when it recorded one.
    scale: Option<f64>,
    /// The run's start, for the tiles' times.
    origin: u64,
    out_dir: PathBuf,
}

impl Sheet<'_> {
    /// Draws capture `i` (stamp `t`, intrinsics `k`) into its PNG and says what is on it.
    fn draw(
        &self,
        i: usize,
        t: u64,
        k: Intrinsics,
        px: Pixels,
    ) -> Result<(ContactFrame, PathBuf), ReportError> {
        let (fw, fh) = (k.width, k.height);
        let sized = |img: Option<fg::RawImage>| img.filter(|m| (m.width, m.height) == (fw, fh));
        let (color, depth, mask) = (sized(px.color), sized(px.depth), sized(px.mask));
        let background = color
            .as_ref()
            .and_then(rgb_of)
            .or_else(|| depth.as_ref().and_then(depth_grey))
            .unwrap_or_else(|| vec![0; fw as usize * fh as usize * 3]);
        let mask = mask
            .filter(|m| m.encoding == "mono8")
            .and_then(|m| Silhouette::from_mono8(fw, fh, &packed_rows(&m, 1)?));
        // The window shown: the whole frame, or (zoom) a crop around the target's mask, which
        // is then drawn the sheet's full width (enlarged if it is smaller).
        let window = self.opts.zoom.and_then(|z| mask.as_ref().and_then(|m| zoom_window(m, z)));
        let (background, mask, k) = crop(&background, mask, &k, window.unwrap_or((0, 0, fw, fh)));
        let (w, h) = (k.width, k.height);
        let (ow, oh) = match window {
            Some(_) => tile_size(w, h, self.opts.max_width),
            None => sheet_size(w, h, self.opts.max_width),
        };
        let mut rgb = resize_u8(&background, 3, (w, h), (ow, oh));
        let sk = k.scaled(ow, oh);
        let gt_pose = pose_at(&self.rec.pose_gt, t);
        let est_pose = pose_at(&self.rec.pose_estimate, t);
        let mask = mask.map(|s| resize_silhouette(&s, ow, oh));
        let model = self.model.as_ref();
        let model_gt = model.zip(gt_pose).map(|(m, p)| rasterize(m, &p, &sk));
        let model_mask_iou = mask.as_ref().zip(model_gt.as_ref()).and_then(|(a, b)| a.iou(b));
        let (gt, source) = match (mask, model_gt) {
            (Some(m), _) => (Some(m), Some(GroundTruthSource::Mask)),
            (None, Some(m)) => (Some(m), Some(GroundTruthSource::Model)),
            (None, None) => (None, None),
        };
        let est = model.zip(est_pose).map(|(m, p)| rasterize(m, &p, &sk));
        if let Some(g) = &gt {
            paint(&mut rgb, &g.outline(), GROUND_TRUTH_COLOUR);
        }
        if let Some(e) = &est {
            paint(&mut rgb, &e.outline(), ESTIMATE_COLOUR);
        }
        let name = format!("{i:03}.png");
        let path = self.out_dir.join(&name);
        write_png(&path, ow, oh, &rgb)
            .map_err(|e| ReportError::Io { path: path.display().to_string(), source: e })?;
        let errors = est_pose.zip(gt_pose).map(|(e, g)| pose::difference(&e, &g));
        let frame = ContactFrame {
            capture: i,
            capture_ns: t,
            t_s: secs(t, self.origin),
            file: format!("{CONTACT_DIR}/{name}"),
            width: ow,
            height: oh,
            ground_truth: source,
            estimate: est.is_some(),
            et_lab_mm: errors.map(|e| e.0 * 1e3),
            et_m: errors.zip(self.scale).map(|(e, s)| e.0 / s),
            er_deg: errors.map(|e| e.1.to_degrees()),
            estimate_iou: est.as_ref().zip(gt.as_ref()).and_then(|(a, b)| a.iou(b)),
            model_mask_iou,
        };
        Ok((frame, path))
    }
}

/// A zoomed tile's size: the crop drawn `max_width` wide, aspect kept (enlarged or shrunk).
fn tile_size(width: u32, height: u32, max_width: u32) -> (u32, u32) {
    if width == 0 || max_width == 0 {
        return (width, height);
    }
    let h = (u64::from(height) * u64::from(max_width) + u64::from(width) / 2) / u64::from(width);
    (max_width, (h as u32).max(1))
}

/// The crop (x0, y0, width, height) around a silhouette's bounding box grown `zoom` times, at
/// the frame's aspect ratio, inside the frame; `None` for an empty silhouette or a window that
/// would be the whole frame anyway.
fn zoom_window(s: &Silhouette, zoom: f64) -> Option<(u32, u32, u32, u32)> {
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
    for y in 0..s.height {
        for x in 0..s.width {
            if s.get(x, y) {
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            }
        }
    }
    if x0 > x1 || !(zoom.is_finite() && zoom >= 1.0) {
        return None;
    }
    let aspect = f64::from(s.width) / f64::from(s.height);
    let (bw, bh) = (f64::from(x1 - x0 + 1) * zoom, f64::from(y1 - y0 + 1) * zoom);
    let cw = bw.max(bh * aspect).max(16.0).min(f64::from(s.width));
    let ch = (cw / aspect).min(f64::from(s.height));
    let (cw, ch) = (cw.round() as u32, ch.round() as u32);
    if cw >= s.width {
        return None;
    }
    let centre = |lo: u32, hi: u32, size: u32, full: u32| {
        let c = (f64::from(lo) + f64::from(hi)) / 2.0 - f64::from(size) / 2.0;
        c.round().clamp(0.0, f64::from(full - size)) as u32
    };
    Some((centre(x0, x1, cw, s.width), centre(y0, y1, ch, s.height), cw, ch))
}

/// The frame's colour, mask and intrinsics cut to `window` (x0, y0, width, height).
fn crop(
    rgb: &[u8],
    mask: Option<Silhouette>,
    k: &Intrinsics,
    (x0, y0, cw, ch): (u32, u32, u32, u32),
) -> (Vec<u8>, Option<Silhouette>, Intrinsics) {
    if (x0, y0, cw, ch) == (0, 0, k.width, k.height) {
        return (rgb.to_vec(), mask, *k);
    }
    let w = k.width as usize;
    let mut out = Vec::with_capacity(cw as usize * ch as usize * 3);
    for y in y0..y0 + ch {
        let row = (y as usize * w + x0 as usize) * 3;
        out.extend_from_slice(&rgb[row..row + cw as usize * 3]);
    }
    let mask = mask.map(|m| {
        let mut c = Silhouette::empty(cw, ch);
        for y in 0..ch {
            for x in 0..cw {
                c.inside[(y * cw + x) as usize] = m.get(x0 + x, y0 + y);
            }
        }
        c
    });
    let kc = Intrinsics {
        width: cw,
        height: ch,
        cx: k.cx - f64::from(x0),
        cy: k.cy - f64::from(y0),
        ..*k
    };
    (out, mask, kc)
}

/// Remove the `.png` files of an earlier sheet (fewer captures now would leave them behind).
fn clear_old_pngs(dir: &Path) -> Result<(), ReportError> {
    for entry in std::fs::read_dir(dir).map_err(super::io(dir))? {
        let path = entry.map_err(super::io(dir))?.path();
        if path.extension().is_some_and(|e| e == "png") && path.is_file() {
            std::fs::remove_file(&path).map_err(super::io(&path))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(half: f64, z: f64) -> TargetMesh {
        TargetMesh {
            vertices: vec![[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]],
            faces: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    fn k(w: u32, h: u32, f: f64) -> Intrinsics {
        Intrinsics {
            width: w,
            height: h,
            fx: f,
            fy: f,
            cx: (w as f64 - 1.0) / 2.0,
            cy: (h as f64 - 1.0) / 2.0,
            distortion: Default::default(),
        }
    }

    #[test]
    fn a_square_fills_the_pixels_whose_centres_it_covers() {
        // 20x10, f = 10, centre (9.5, 4.5); a square of half-size 0.3 m at 1 m spans 3 px either
        // side of the centre: x in [6.5, 12.5] -> 7..=12, y in [1.5, 7.5] -> 2..=7.
        let s = rasterize(&square(0.3, 0.0), &Pose::translation(0.0, 0.0, 1.0), &k(20, 10, 10.0));
        for y in 0..10 {
            for x in 0..20 {
                assert_eq!(
                    s.get(x, y),
                    (7..=12).contains(&x) && (2..=7).contains(&y),
                    "({x}, {y})"
                );
            }
        }
        assert_eq!(s.area(), 36);
        // Its outline is the ring of 6x6: 20 pixels.
        let o = s.outline();
        assert_eq!(o.area(), 20);
        assert!(o.get(7, 2) && o.get(12, 7) && !o.get(9, 4));
    }

    #[test]
    fn behind_the_camera_draws_nothing() {
        let p = Pose::translation(0.0, 0.0, -1.0);
        assert_eq!(rasterize(&square(0.3, 0.0), &p, &k(20, 10, 10.0)).area(), 0);
    }

    #[test]
    fn rasterising_at_the_shrunk_size_matches_shrinking_the_full_raster() {
        // 1280x800 -> 480x300; a tilted square off centre.
        let (w, h) = (1280, 800);
        let full_k = Intrinsics {
            width: w,
            height: h,
            fx: 900.0,
            fy: 900.0,
            cx: 650.3,
            cy: 390.8,
            distortion: Default::default(),
        };
        let (ow, oh) = sheet_size(w, h, 480);
        assert_eq!((ow, oh), (480, 300));
        let a = 0.4f64;
        let pose = Pose::new(nalgebra::Vector3::new(0.12, -0.05, 1.5), nalgebra::Vector3::x() * a);
        let mesh = square(0.25, 0.0);
        let full = rasterize(&mesh, &pose, &full_k);
        let shrunk = resize_silhouette(&full, ow, oh);
        let direct = rasterize(&mesh, &pose, &full_k.scaled(ow, oh));
        let iou = shrunk.iou(&direct).expect("same size");
        assert!(iou > 0.97, "IoU {iou}");
        assert!(direct.area() > 2000, "{}", direct.area());
    }

    #[test]
    fn the_zoom_crops_around_the_mask_at_the_frames_aspect_and_moves_the_principal_point() {
        // A 10x5 target at (100..110, 50..55) in a 320x160 frame, zoomed 4x: a 40x20 window
        // (2:1 like the frame) centred on it.
        let mut m = Silhouette::empty(320, 160);
        for y in 50..55 {
            for x in 100..110 {
                m.inside[y * 320 + x] = true;
            }
        }
        let win = zoom_window(&m, 4.0).expect("window");
        assert_eq!(win, (85, 42, 40, 20));
        let rgb: Vec<u8> = (0..320 * 160 * 3).map(|i| (i / 3 % 320) as u8).collect();
        let (c, cm, ck) = crop(&rgb, Some(m.clone()), &k(320, 160, 100.0), win);
        assert_eq!((ck.width, ck.height, ck.cx, ck.cy), (40, 20, 159.5 - 85.0, 79.5 - 42.0));
        assert_eq!(c.len(), 40 * 20 * 3);
        assert_eq!(c[0], 85); // the first pixel of the crop is column 85 of the frame
        let cm = cm.expect("mask");
        assert_eq!(cm.area(), m.area());
        assert!(cm.get(100 - 85, 50 - 42) && !cm.get(0, 0));
        // An empty mask, or a zoom that would show the whole frame, keeps the whole frame.
        assert_eq!(zoom_window(&Silhouette::empty(320, 160), 4.0), None);
        assert_eq!(zoom_window(&m, 100.0), None);
    }

    #[test]
    fn the_box_filter_averages_and_keeps_size_when_small() {
        // 4x2 grey ramp -> 2x1: each output the mean of a 2x2 block.
        let src: Vec<u8> =
            [0u8, 10, 20, 30, 40, 50, 60, 70].iter().flat_map(|&v| [v, v, v]).collect();
        let out = shrink_u8(&src, 3, (4, 2), (2, 1));
        assert_eq!(out, vec![25, 25, 25, 45, 45, 45]);
        assert_eq!(sheet_size(96, 64, 480), (96, 64));
        assert_eq!(sheet_size(1280, 1024, 480), (480, 384));
        assert_eq!(spread(41, 8), vec![0, 5, 11, 17, 22, 28, 34, 40]);
        assert_eq!(spread(3, 8), vec![0, 1, 2]);
    }
}
