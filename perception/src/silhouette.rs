//! The target's silhouette drawn from a pose: the mask a real camera's frame gets (`hitl run
//! --mask rendered`, docs/perception.md).
//!
//! A small z-buffer rasteriser of triangle meshes: the target mesh and, optionally, fixed
//! occluders given in the target's frame (the tripod it stands on) are projected with a pinhole
//! camera's intrinsics (pixel centres at integer coordinates, as [`Intrinsics`] says), clipped
//! at a near plane, and filled; a pixel whose centre the nearest surface there belongs to the
//! target is target. The mask is then grown by a margin of whole pixels (a disc), which covers
//! calibration and timing error.
//!
//! Not a crate: the 2-D raster crates (tiny-skia and the like) fill paths with anti-aliasing but
//! have no depth test, which the occluders need; a triangle fill with a depth test is a few
//! dozen lines. Scratch buffers are kept between frames, so drawing a frame allocates nothing
//! once the first frame of a size has been drawn.

use crate::models::Mesh;
use crate::PerceptionError;
use hitl_hal::{Intrinsics, Pose};
use nalgebra::{Point3, Vector3};

/// Mask value of a target pixel (mono8: 255 target, 0 else).
pub const TARGET: u8 = 255;

/// Surfaces nearer than this to the camera (metres along its axis) are cut away.
const NEAR_M: f64 = 1e-4;

/// What one drawing gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Drawn {
    /// Target pixels before the margin (the silhouette as drawn).
    pub silhouette_px: usize,
    /// Target pixels after the margin.
    pub mask_px: usize,
    /// The drawn target's box before the margin, pixels (u0, v0, u1, v1 inclusive); none when
    /// the target is out of view.
    pub window: Option<[usize; 4]>,
}

/// Draws a target's silhouette, with fixed occluders, from any camera pose.
#[derive(Debug, Clone)]
pub struct SilhouetteRenderer {
    /// Target, then occluder vertices, target frame.
    vertices: Vec<Vector3<f64>>,
    /// Triangles: indices and whether they belong to the target.
    faces: Vec<([u32; 3], bool)>,
    /// Scratch: depth and owner per pixel; the margin's copy.
    depth: Vec<f32>,
    owner: Vec<u8>,
    /// The face seen at each pixel, kept only when asked for ([`Self::with_faces`]).
    face: Vec<u32>,
    keep_faces: bool,
    grown: Vec<u8>,
    disc: Vec<(i32, i32)>,
    disc_radius: u32,
    /// Scratch: each vertex in the camera frame and its pixel (NaN behind the near plane), so a
    /// vertex shared by several faces is moved and projected once.
    cam: Vec<Vector3<f64>>,
    uv: Vec<(f64, f64)>,
}

impl SilhouetteRenderer {
    /// A renderer of `target` (the mesh as the camera sees it: lab metres, body frame).
    /// Refuses a mesh that cannot be drawn (no triangle of non-zero area, a vertex that is not
    /// finite; [`Mesh::new`] already refuses both, this is checked again for any mesh).
    pub fn new(target: &Mesh) -> Result<Self, PerceptionError> {
        let vertices: Vec<Vector3<f64>> =
            target.vertices().iter().map(|v| Vector3::new(v[0], v[1], v[2])).collect();
        if vertices.iter().any(|v| !v.iter().all(|c| c.is_finite())) {
            return Err(PerceptionError::BadMesh("cannot draw: a vertex is not finite".into()));
        }
        let faces: Vec<([u32; 3], bool)> = target.faces().iter().map(|f| (*f, true)).collect();
        let drawable = faces.iter().any(|(f, _)| {
            let [a, b, c] = f.map(|i| vertices[i as usize]);
            (b - a).cross(&(c - a)).norm() > 0.0
        });
        if !drawable {
            return Err(PerceptionError::BadMesh(
                "cannot draw the target's silhouette: no triangle has an area".into(),
            ));
        }
        Ok(Self {
            vertices,
            faces,
            depth: Vec::new(),
            owner: Vec::new(),
            face: Vec::new(),
            keep_faces: false,
            grown: Vec::new(),
            disc: Vec::new(),
            disc_radius: 0,
            cam: Vec::new(),
            uv: Vec::new(),
        })
    }

    /// Keeps the face seen at each pixel ([`Self::face_at`]): a pose refined by drawing the
    /// target needs each pixel's exact surface normal.
    pub fn with_faces(mut self) -> Self {
        self.keep_faces = true;
        self
    }

    /// The target face (index into the mesh's faces) drawn at pixel `idx`, valid as
    /// [`Self::surface_depth`] is; `None` unless kept ([`Self::with_faces`]).
    pub fn face_at(&self, idx: usize) -> Option<usize> {
        self.face.get(idx).map(|&f| f as usize)
    }

    /// Adds a fixed occluder (vertices in the target's frame): what it hides is not target.
    pub fn with_occluder(mut self, vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Self {
        let base = self.vertices.len() as u32;
        let n = vertices.len() as u32;
        self.vertices.extend(vertices.iter().map(|v| Vector3::new(v[0], v[1], v[2])));
        self.faces.extend(
            faces
                .iter()
                .filter(|f| f.iter().all(|&i| i < n))
                .map(|f| ([f[0] + base, f[1] + base, f[2] + base], false)),
        );
        self
    }

    /// Draws the target at `camera_t_target` (OpenCV camera axes) into `mask` (resized to the
    /// image, row-major, [`TARGET`] or 0), grown by `margin_px` pixels.
    pub fn draw(
        &mut self,
        camera_t_target: &Pose,
        k: &Intrinsics,
        margin_px: u32,
        mask: &mut Vec<u8>,
    ) -> Drawn {
        let (w, h) = (k.width as usize, k.height as usize);
        let n = w * h;
        mask.clear();
        mask.resize(n, 0);
        if n == 0 || !(k.fx > 0.0 && k.fy > 0.0) {
            return Drawn::default();
        }
        if self.depth.len() != n {
            self.depth = vec![f32::INFINITY; n];
            self.owner = vec![0; n];
        }
        if self.keep_faces && self.face.len() != n {
            self.face = vec![0; n];
        }
        let r = camera_t_target.rotation.to_rotation_matrix();
        let t = camera_t_target.translation.vector;
        self.cam.clear();
        self.cam.extend(self.vertices.iter().map(|v| r * v + t));
        self.uv.clear();
        self.uv.extend(self.cam.iter().map(|q| {
            if q.z >= NEAR_M {
                k.project(q.x, q.y, q.z)
            } else {
                (f64::NAN, f64::NAN)
            }
        }));
        let in_front =
            |f: &[u32; 3], cam: &[Vector3<f64>]| f.iter().all(|&i| cam[i as usize].z >= NEAR_M);
        // Only the target's box in the image is drawn, cleared and scanned: the rest is 0.
        let mut bx = Window::EMPTY;
        for &(f, is_target) in &self.faces {
            if !is_target {
                continue;
            }
            if in_front(&f, &self.cam) {
                for i in f {
                    let (u, v) = self.uv[i as usize];
                    bx.add(u, v);
                }
                continue;
            }
            let tri = f.map(|i| self.cam[i as usize]);
            let mut poly = [Vector3::zeros(); 4];
            let m = clip_near(&tri, &mut poly);
            for q in &poly[..m] {
                let (u, v) = k.project(q.x, q.y, q.z);
                bx.add(u, v);
            }
        }
        let Some(bx) = bx.in_image(w, h) else {
            return Drawn::default();
        };
        for v in bx.v0..=bx.v1 {
            self.depth[v * w + bx.u0..=v * w + bx.u1].fill(f32::INFINITY);
            self.owner[v * w + bx.u0..=v * w + bx.u1].fill(0);
        }
        let mut raster = Raster {
            w,
            h: k.height as usize,
            bx: &bx,
            depth: &mut self.depth,
            owner: &mut self.owner,
            face: &mut self.face,
        };
        for (id, &(f, is_target)) in self.faces.iter().enumerate() {
            let drawn = Drawing { is_target, id: id as u32 };
            if in_front(&f, &self.cam) {
                let uv = f.map(|i| self.uv[i as usize]);
                let iz = f.map(|i| 1.0 / self.cam[i as usize].z);
                raster.fill(uv, iz, drawn);
                continue;
            }
            let tri = f.map(|i| self.cam[i as usize]);
            let mut poly = [Vector3::zeros(); 4];
            let m = clip_near(&tri, &mut poly);
            // A convex polygon of 3 or 4 corners: a fan of triangles.
            for j in 1..m.saturating_sub(1) {
                let p = [poly[0], poly[j], poly[j + 1]];
                raster.fill(p.map(|q| k.project(q.x, q.y, q.z)), p.map(|q| 1.0 / q.z), drawn);
            }
        }
        let mut silhouette_px = 0;
        for v in bx.v0..=bx.v1 {
            let row = v * w;
            let span = row + bx.u0..=row + bx.u1;
            for (m, &o) in mask[span.clone()].iter_mut().zip(&self.owner[span]) {
                if o == 1 {
                    *m = TARGET;
                    silhouette_px += 1;
                }
            }
        }
        let mut mask_px = silhouette_px;
        if margin_px > 0 && silhouette_px > 0 {
            mask_px = self.grow(mask, w, h, &bx, margin_px);
        }
        Drawn { silhouette_px, mask_px, window: Some([bx.u0, bx.v0, bx.u1, bx.v1]) }
    }

    /// The drawn surface's depth (metres along the camera axis) at pixel `idx`, valid after a
    /// [`Self::draw`] with margin 0 for a pixel its mask marks [`TARGET`] (elsewhere it may be
    /// left from an earlier drawing).
    pub fn surface_depth(&self, idx: usize) -> Option<f32> {
        self.depth.get(idx).copied().filter(|d| d.is_finite())
    }

    /// Grows `mask` by a disc of `radius` pixels: every pixel within `radius` of a target pixel
    /// becomes target (stamped from the silhouette's boundary pixels, all inside `bx`). Returns
    /// the target pixels after.
    fn grow(&mut self, mask: &mut [u8], w: usize, h: usize, bx: &Window, radius: u32) -> usize {
        if self.disc_radius != radius || self.disc.is_empty() {
            let r = radius as i32;
            let r2 = f64::from(radius).powi(2) + 0.5;
            self.disc = (-r..=r)
                .flat_map(|dv| (-r..=r).map(move |du| (du, dv)))
                .filter(|&(du, dv)| f64::from(du * du + dv * dv) <= r2)
                .collect();
            self.disc_radius = radius;
        }
        let (wi, hi) = (w as i32, h as i32);
        // The grown window, whose pixels are the only ones that can change.
        let g = radius as usize;
        let (gu0, gv0) = (bx.u0.saturating_sub(g), bx.v0.saturating_sub(g));
        let (gu1, gv1) = ((bx.u1 + g).min(w - 1), (bx.v1 + g).min(h - 1));
        self.grown.clear();
        self.grown.resize(mask.len(), 0);
        for v in gv0..=gv1 {
            let row = v * w;
            self.grown[row + gu0..=row + gu1].copy_from_slice(&mask[row + gu0..=row + gu1]);
        }
        for v in bx.v0..=bx.v1 {
            for u in bx.u0..=bx.u1 {
                if mask[v * w + u] == 0 {
                    continue;
                }
                let inner = u > 0
                    && v > 0
                    && u + 1 < w
                    && v + 1 < h
                    && mask[v * w + u - 1] != 0
                    && mask[v * w + u + 1] != 0
                    && mask[(v - 1) * w + u] != 0
                    && mask[(v + 1) * w + u] != 0;
                if inner {
                    continue;
                }
                for &(du, dv) in &self.disc {
                    let (uu, vv) = (u as i32 + du, v as i32 + dv);
                    if uu >= 0 && vv >= 0 && uu < wi && vv < hi {
                        self.grown[vv as usize * w + uu as usize] = TARGET;
                    }
                }
            }
        }
        let mut count = 0;
        for v in gv0..=gv1 {
            let row = v * w;
            let src = &self.grown[row + gu0..=row + gu1];
            count += src.iter().filter(|&&m| m != 0).count();
            mask[row + gu0..=row + gu1].copy_from_slice(src);
        }
        count
    }
}

/// A window of the image, pixels (inclusive).
#[derive(Debug, Clone, Copy)]
struct Window {
    u0: usize,
    v0: usize,
    u1: usize,
    v1: usize,
}

/// Bounds of projected points, before they are cut to the image.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    lo_u: f64,
    lo_v: f64,
    hi_u: f64,
    hi_v: f64,
}

impl Window {
    const EMPTY: Bounds = Bounds {
        lo_u: f64::INFINITY,
        lo_v: f64::INFINITY,
        hi_u: f64::NEG_INFINITY,
        hi_v: f64::NEG_INFINITY,
    };
}

impl Bounds {
    fn add(&mut self, u: f64, v: f64) {
        self.lo_u = self.lo_u.min(u);
        self.lo_v = self.lo_v.min(v);
        self.hi_u = self.hi_u.max(u);
        self.hi_v = self.hi_v.max(v);
    }

    /// The pixel centres inside, cut to a `w` x `h` image; `None` if there is none.
    fn in_image(&self, w: usize, h: usize) -> Option<Window> {
        let ok = [self.lo_u, self.lo_v, self.hi_u, self.hi_v].iter().all(|x| !x.is_nan());
        if !ok || self.hi_u < 0.0 || self.hi_v < 0.0 {
            return None;
        }
        if self.lo_u > (w - 1) as f64 || self.lo_v > (h - 1) as f64 {
            return None;
        }
        let u0 = self.lo_u.ceil().max(0.0) as usize;
        let v0 = self.lo_v.ceil().max(0.0) as usize;
        let u1 = (self.hi_u.floor().min((w - 1) as f64)) as usize;
        let v1 = (self.hi_v.floor().min((h - 1) as f64)) as usize;
        (u0 <= u1 && v0 <= v1).then_some(Window { u0, v0, u1, v1 })
    }
}

/// Clips a camera-frame triangle against the plane z = [`NEAR_M`]; the corners of what is left
/// (0, 3 or 4) go to `out`, their count is returned.
fn clip_near(tri: &[Vector3<f64>; 3], out: &mut [Vector3<f64>; 4]) -> usize {
    let mut m = 0;
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        let (ina, inb) = (a.z >= NEAR_M, b.z >= NEAR_M);
        if ina {
            out[m] = a;
            m += 1;
        }
        if ina != inb && m < 4 {
            let s = (NEAR_M - a.z) / (b.z - a.z);
            out[m] = a + (b - a) * s;
            m += 1;
        }
    }
    m
}

/// Edge function: twice the signed area of (a, b, c) in the image.
fn edge(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// What a filled triangle is: the target's or an occluder's, and its index.
#[derive(Debug, Clone, Copy)]
struct Drawing {
    is_target: bool,
    id: u32,
}

/// The buffers one drawing fills, inside the window `bx`.
struct Raster<'a> {
    w: usize,
    h: usize,
    bx: &'a Window,
    depth: &'a mut [f32],
    owner: &'a mut [u8],
    face: &'a mut [u32],
}

impl Raster<'_> {
    /// Fills one triangle in front of the near plane, given by its corners' pixels `uv` and
    /// inverse depths `iz`, with a depth test into the depth and owner buffers (and `face`,
    /// unless it is empty).
    fn fill(&mut self, uv: [(f64, f64); 3], iz: [f64; 3], drawn: Drawing) {
        let area = edge(uv[0], uv[1], uv[2]);
        if area.abs() < 1e-12 || !area.is_finite() {
            return;
        }
        let mut b = Window::EMPTY;
        for (u, v) in uv {
            b.add(u, v);
        }
        let Some(tb) = b.in_image(self.w, self.h) else {
            return;
        };
        let bx = self.bx;
        let (u0, v0) = (tb.u0.max(bx.u0), tb.v0.max(bx.v0));
        let (u1, v1) = (tb.u1.min(bx.u1), tb.v1.min(bx.v1));
        if u0 > u1 || v0 > v1 {
            return;
        }
        let inv = 1.0 / area;
        let label = if drawn.is_target { 1 } else { 2 };
        for v in v0..=v1 {
            let row = v * self.w;
            for u in u0..=u1 {
                let q = (u as f64, v as f64);
                let b0 = edge(uv[1], uv[2], q) * inv;
                let b1 = edge(uv[2], uv[0], q) * inv;
                let b2 = edge(uv[0], uv[1], q) * inv;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                // 1/z is affine in the image: perspective-correct depth.
                let z = (1.0 / (b0 * iz[0] + b1 * iz[1] + b2 * iz[2])) as f32;
                let i = row + u;
                if z < self.depth[i] {
                    self.depth[i] = z;
                    self.owner[i] = label;
                    if let Some(f) = self.face.get_mut(i) {
                        *f = drawn.id;
                    }
                }
            }
        }
    }
}

/// A closed triangle mesh of a capsule (the segment `a`-`b` swept by a sphere of `radius`):
/// `segments` around, `rings` per half-sphere. Vertices and triangles, for an occluder.
pub fn capsule_mesh(
    a: Point3<f64>,
    b: Point3<f64>,
    radius: f64,
    segments: usize,
    rings: usize,
) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let segments = segments.max(3);
    let rings = rings.max(1);
    let axis = b - a;
    let len = axis.norm();
    let z = if len > 1e-12 { axis / len } else { Vector3::z() };
    let helper = if z.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let x = helper.cross(&z).normalize();
    let y = z.cross(&x);
    // Latitude rings from the bottom pole (at a) to the top pole (at b).
    let mut lat: Vec<(f64, Point3<f64>)> = Vec::new();
    for i in 0..=rings {
        let phi = -std::f64::consts::FRAC_PI_2 * (1.0 - i as f64 / rings as f64);
        lat.push((phi, a));
    }
    for i in 0..=rings {
        let phi = std::f64::consts::FRAC_PI_2 * i as f64 / rings as f64;
        lat.push((phi, b));
    }
    let mut vertices = Vec::new();
    for (phi, centre) in &lat {
        for s in 0..segments {
            let th = std::f64::consts::TAU * s as f64 / segments as f64;
            let d = (x * th.cos() + y * th.sin()) * phi.cos() + z * phi.sin();
            let p = centre + d * radius;
            vertices.push([p.x, p.y, p.z]);
        }
    }
    let mut faces = Vec::new();
    let seg = segments as u32;
    for ring in 0..lat.len() as u32 - 1 {
        for s in 0..seg {
            let (i0, i1) = (ring * seg + s, ring * seg + (s + 1) % seg);
            let (j0, j1) = (i0 + seg, i1 + seg);
            faces.push([i0, i1, j1]);
            faces.push([i0, j1, j0]);
        }
    }
    (vertices, faces)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::TargetModel;
    use crate::testing::{intrinsics_hfov, look_pose, render};

    fn iou(a: &[u8], b: &[u8]) -> f64 {
        let inter = a.iter().zip(b).filter(|(x, y)| **x != 0 && **y != 0).count();
        let union = a.iter().zip(b).filter(|(x, y)| **x != 0 || **y != 0).count();
        inter as f64 / union.max(1) as f64
    }

    #[test]
    fn the_silhouette_is_the_rendered_targets_and_the_margin_grows_it() {
        let mesh = TargetModel::from_spec("asymmetric").expect("built-in").mesh;
        let k = intrinsics_hfov(320, 256, 60.0);
        let pose = look_pose(6.0, 0.4, -0.3, 0.9);
        let reference = render(&mesh, &pose, &k, 0).mask.expect("mask");
        let mut r = SilhouetteRenderer::new(&mesh).expect("drawable");
        let mut mask = Vec::new();
        let d = r.draw(&pose, &k, 0, &mut mask);
        assert!(d.silhouette_px > 300, "{d:?}");
        assert_eq!(d.mask_px, d.silhouette_px);
        assert!(iou(&mask, &reference) > 0.99, "iou {}", iou(&mask, &reference));
        let grown = r.draw(&pose, &k, 2, &mut mask);
        assert!(grown.mask_px > d.silhouette_px, "{grown:?}");
        // Every silhouette pixel is kept, and every added pixel is within 2 px of one.
        let (w, h) = (k.width as i32, k.height as i32);
        for v in 0..h {
            for u in 0..w {
                let i = (v * w + u) as usize;
                if reference[i] != 0 {
                    assert_eq!(mask[i], TARGET);
                }
                if mask[i] != 0 && reference[i] == 0 {
                    let near = (-2..=2).any(|dv: i32| {
                        (-2..=2).any(|du: i32| {
                            let (uu, vv) = (u + du, v + dv);
                            uu >= 0
                                && vv >= 0
                                && uu < w
                                && vv < h
                                && reference[(vv * w + uu) as usize] != 0
                        })
                    });
                    assert!(near, "pixel {u},{v} is beyond the margin");
                }
            }
        }
    }

    #[test]
    fn an_occluder_in_front_hides_the_target_and_out_of_view_is_empty() {
        let mesh = TargetModel::from_spec("two-planes").expect("built-in").mesh;
        let k = intrinsics_hfov(160, 128, 60.0);
        let pose = look_pose(5.0, 0.0, 0.0, 0.0);
        let mut free = SilhouetteRenderer::new(&mesh).expect("drawable");
        let mut mask = Vec::new();
        let all = free.draw(&pose, &k, 0, &mut mask).silhouette_px;
        // A capsule 2 m in front of the target (towards the camera), across the image's middle.
        let (v, f) =
            capsule_mesh(Point3::new(-3.0, 0.0, -2.0), Point3::new(3.0, 0.0, -2.0), 0.1, 16, 4);
        let mut hidden = SilhouetteRenderer::new(&mesh).expect("drawable").with_occluder(&v, &f);
        let part = hidden.draw(&pose, &k, 0, &mut mask).silhouette_px;
        assert!(part > 0 && part < all, "{part} of {all}");
        let mid = (k.height as usize / 2) * k.width as usize + k.width as usize / 2;
        assert_eq!(mask[mid], 0, "the capsule covers the middle");
        // Behind the camera: nothing; a capsule through the camera plane is clipped, not drawn
        // inverted.
        let behind = look_pose(-5.0, 0.0, 0.0, 0.0);
        assert_eq!(free.draw(&behind, &k, 3, &mut mask), Drawn::default());
        assert!(mask.iter().all(|&m| m == 0));
        let (v, f) =
            capsule_mesh(Point3::new(0.0, 2.0, -10.0), Point3::new(0.0, 2.0, 10.0), 0.2, 16, 4);
        let mut through = SilhouetteRenderer::new(&mesh).expect("drawable").with_occluder(&v, &f);
        assert_eq!(through.draw(&pose, &k, 0, &mut mask).silhouette_px, all);
    }
}
