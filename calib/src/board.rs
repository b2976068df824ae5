//! The calibration board: an AprilGrid (a grid of tag36h11 AprilTags) and its printable drawing.
//!
//! The tags' bit patterns come from the detection library's own family table (the AprilTag C
//! library's tag36h11: `codes`, `bit_x`, `bit_y`, read in [`crate::family`]), drawn the
//! way the AprilTag reference implementation draws a tag (`apriltag_to_image`): a black square
//! of `width_at_border` (8) cells with a white ring of one cell around it; code bit `nbits-1-i`
//! set makes cell (`bit_x[i]`, `bit_y[i]`) of the black square white. So what is printed is
//! exactly what the detector decodes.
//!
//! Board frame (the lab configuration's [`BoardPlacement`]): origin at the outer top-left corner
//! of the first tag's black square, x to the right along a row, y down a column, z into the board.

use hitl_trajectories::lab::BoardPlacement;
use nalgebra::Point3;
use std::fmt::Write as _;

/// Why a board definition was refused.
#[derive(Debug, thiserror::Error)]
pub enum BoardError {
    #[error("board: {0}")]
    Invalid(String),
    #[error("cannot read board file {path}: {message}")]
    Read { path: String, message: String },
}

/// A board file (calib/boards/*.toml): the `[board]` table of a lab configuration.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct BoardFile {
    board: BoardPlacement,
}

/// Read a board file (a TOML file with one `[board]` table, the lab configuration's).
pub fn load_board_file(path: &std::path::Path) -> Result<BoardPlacement, BoardError> {
    let read = |message: String| BoardError::Read { path: path.display().to_string(), message };
    let text = std::fs::read_to_string(path).map_err(|e| read(e.to_string()))?;
    let file: BoardFile = toml::from_str(&text).map_err(|e| read(e.to_string()))?;
    Board::new(&file.board)?;
    Ok(file.board)
}

/// Cells across a tag36h11 black square (`width_at_border`).
pub const TAG_CELLS: usize = 8;

/// A validated board with its tags' cell patterns.
#[derive(Debug, Clone)]
pub struct Board {
    pub placement: BoardPlacement,
    /// Per tag (row-major), `TAG_CELLS`x`TAG_CELLS` cells, row-major, `true` = black.
    patterns: Vec<[[bool; TAG_CELLS]; TAG_CELLS]>,
}

impl Board {
    /// Check `p` and build the patterns from the detector's family table.
    pub fn new(p: &BoardPlacement) -> Result<Self, BoardError> {
        let bad = |m: String| Err(BoardError::Invalid(m));
        if p.family != "tag36h11" {
            return bad(format!("family {:?}: only tag36h11 is supported", p.family));
        }
        if !(1..=20).contains(&p.rows) || !(1..=20).contains(&p.cols) {
            return bad(format!("{}x{} tags: rows and cols must be 1-20", p.rows, p.cols));
        }
        if !(p.tag_size_m > 0.0 && p.tag_size_m < 1.0) {
            return bad(format!("tag_size_m = {} must be in (0, 1) m", p.tag_size_m));
        }
        if !(p.tag_spacing_m >= 0.0 && p.tag_spacing_m < 1.0) {
            return bad(format!("tag_spacing_m = {} must be in [0, 1) m", p.tag_spacing_m));
        }
        if p.position_target_m.iter().chain(&p.rpy_deg).any(|v| !v.is_finite()) {
            return bad("position_target_m and rpy_deg must be finite".into());
        }
        let family = crate::family::tag36h11();
        let n = (p.rows * p.cols) as usize;
        let last = p.first_id as usize + n;
        if last > family.codes.len() {
            return bad(format!(
                "tags {}..{} do not exist: tag36h11 has {} codes",
                p.first_id,
                last - 1,
                family.codes.len()
            ));
        }
        if family.width_at_border != TAG_CELLS {
            return bad(format!("tag36h11 width {} != {TAG_CELLS}", family.width_at_border));
        }
        let patterns = (0..n)
            .map(|k| {
                let code = family.codes[p.first_id as usize + k];
                let mut cells = [[true; TAG_CELLS]; TAG_CELLS];
                for i in 0..family.nbits {
                    if code & (1u64 << (family.nbits - i - 1)) != 0 {
                        let (x, y) = (family.bit_x[i] as usize, family.bit_y[i] as usize);
                        cells[y][x] = false;
                    }
                }
                cells
            })
            .collect();
        Ok(Self { placement: p.clone(), patterns })
    }

    pub fn rows(&self) -> usize {
        self.placement.rows as usize
    }

    pub fn cols(&self) -> usize {
        self.placement.cols as usize
    }

    pub fn tag_count(&self) -> usize {
        self.rows() * self.cols()
    }

    /// Distance between neighbouring tags' origins, metres.
    pub fn pitch_m(&self) -> f64 {
        self.placement.tag_size_m + self.placement.tag_spacing_m
    }

    /// Width and height of the tag grid (outer edges of the black squares), metres.
    pub fn extent_m(&self) -> (f64, f64) {
        let s = self.placement.tag_size_m;
        let g = self.placement.tag_spacing_m;
        (
            self.cols() as f64 * s + (self.cols() - 1) as f64 * g,
            self.rows() as f64 * s + (self.rows() - 1) as f64 * g,
        )
    }

    /// Index (row-major) of tag `id`, if it is on this board.
    pub fn index_of(&self, id: u32) -> Option<usize> {
        let k = id.checked_sub(self.placement.first_id)? as usize;
        (k < self.tag_count()).then_some(k)
    }

    /// Tag id at index `k`.
    pub fn id_of(&self, k: usize) -> u32 {
        self.placement.first_id + k as u32
    }

    /// The four outer corners of tag index `k`'s black square in the board frame, in the order
    /// top-left, top-right, bottom-right, bottom-left (as printed).
    pub fn corners(&self, k: usize) -> [Point3<f64>; 4] {
        let (row, col) = (k / self.cols(), k % self.cols());
        let p = self.pitch_m();
        let s = self.placement.tag_size_m;
        let (x, y) = (col as f64 * p, row as f64 * p);
        [
            Point3::new(x, y, 0.0),
            Point3::new(x + s, y, 0.0),
            Point3::new(x + s, y + s, 0.0),
            Point3::new(x, y + s, 0.0),
        ]
    }

    /// Black cells of tag index `k`: (cell row, cell col) -> black.
    pub fn pattern(&self, k: usize) -> &[[bool; TAG_CELLS]; TAG_CELLS] {
        &self.patterns[k]
    }

    /// Black rectangles of the whole board in the board frame (x, y, width, height), metres:
    /// each tag's black cells merged into horizontal runs. The drawing and the stub's scene both
    /// use these.
    pub fn black_rects(&self) -> Vec<[f64; 4]> {
        let cell = self.placement.tag_size_m / TAG_CELLS as f64;
        let mut out = Vec::new();
        for k in 0..self.tag_count() {
            let o = self.corners(k)[0];
            for (r, row) in self.patterns[k].iter().enumerate() {
                let mut c = 0;
                while c < TAG_CELLS {
                    if !row[c] {
                        c += 1;
                        continue;
                    }
                    let start = c;
                    while c < TAG_CELLS && row[c] {
                        c += 1;
                    }
                    out.push([
                        o.x + start as f64 * cell,
                        o.y + r as f64 * cell,
                        (c - start) as f64 * cell,
                        cell,
                    ]);
                }
            }
        }
        out
    }

    /// A one-line description for provenance blocks and messages.
    pub fn describe(&self) -> String {
        let p = &self.placement;
        format!(
            "aprilgrid {}x{} {} tags {:.1} mm, gap {:.1} mm, ids {}-{}",
            p.rows,
            p.cols,
            p.family,
            p.tag_size_m * 1e3,
            p.tag_spacing_m * 1e3,
            p.first_id,
            self.id_of(self.tag_count() - 1)
        )
    }

    /// The board as an SVG drawing true to scale: width and height in millimetres, a white
    /// quiet zone of one tag around the grid, a 100 mm scale bar and the board's description.
    pub fn svg(&self) -> String {
        let mm = 1e3;
        let margin = self.placement.tag_size_m * mm;
        let (w, h) = self.extent_m();
        let (w, h) = (w * mm, h * mm);
        let footer = 16.0;
        let (tw, th) = (w + 2.0 * margin, h + 2.0 * margin + footer);
        let mut s = String::new();
        let _ = writeln!(s, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>");
        let _ = writeln!(
            s,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{tw:.3}mm\" height=\"{th:.3}mm\" viewBox=\"0 0 {tw:.3} {th:.3}\">"
        );
        let _ = writeln!(
            s,
            "<rect x=\"0\" y=\"0\" width=\"{tw:.3}\" height=\"{th:.3}\" fill=\"#fff\"/>"
        );
        let _ = writeln!(s, "<g fill=\"#000\" shape-rendering=\"crispEdges\">");
        for [x, y, rw, rh] in self.black_rects() {
            let _ = writeln!(
                s,
                "<rect x=\"{:.4}\" y=\"{:.4}\" width=\"{:.4}\" height=\"{:.4}\"/>",
                margin + x * mm,
                margin + y * mm,
                rw * mm,
                rh * mm
            );
        }
        let _ = writeln!(s, "</g>");
        let y0 = h + 2.0 * margin;
        let bar = 100.0f64.min(w);
        let _ = writeln!(
            s,
            "<rect x=\"{margin:.3}\" y=\"{:.3}\" width=\"{bar:.3}\" height=\"1.5\" fill=\"#000\"/>",
            y0 + 1.0
        );
        let _ = writeln!(
            s,
            "<text x=\"{margin:.3}\" y=\"{:.3}\" font-family=\"sans-serif\" font-size=\"3.5\">{} | bar {bar:.0} mm: print at 100 %, measure the tag size, write it in tag_size_m</text>",
            y0 + 8.0,
            self.describe()
        );
        let _ = writeln!(s, "</svg>");
        s
    }

    /// A frontal grey image of the board (for tests): `px_per_m` pixels per metre, a white border
    /// of `border_px`. Pixel (u, v) covers board (x, y) = ((u - border) / px_per_m, ...).
    pub fn render_frontal(&self, px_per_m: f64, border_px: usize) -> (usize, usize, Vec<u8>) {
        let (w, h) = self.extent_m();
        let width = (w * px_per_m).ceil() as usize + 2 * border_px;
        let height = (h * px_per_m).ceil() as usize + 2 * border_px;
        let mut img = vec![255u8; width * height];
        for [x, y, rw, rh] in self.black_rects() {
            let u0 = (x * px_per_m).round() as usize + border_px;
            let v0 = (y * px_per_m).round() as usize + border_px;
            let u1 = ((x + rw) * px_per_m).round() as usize + border_px;
            let v1 = ((y + rh) * px_per_m).round() as usize + border_px;
            for v in v0..v1.min(height) {
                for u in u0..u1.min(width) {
                    img[v * width + u] = 0;
                }
            }
        }
        (width, height, img)
    }
}
