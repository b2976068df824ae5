//! The project's own procedural spacecraft, one per symmetry class of the paper, each centred and
//! scaled so its greatest dimension is 2 m:
//! - `two-planes`: box bus, two equal solar wings on a boom along +-x, antenna dish on +z
//!   (mirror planes x = 0 and y = 0);
//! - `one-plane`: the same bus and dish with a single wing on +x (mirror plane y = 0);
//! - `asymmetric`: one wing on +x, the dish off-centre on +z and a thruster block off-centre on -z
//!   (no mirror plane).
//!
//! Each is built twice from the same calls: one merged mesh for the estimators (vertex for vertex
//! what it always was) and, for the renderer, one part per material: the bus in gold MLI foil,
//! the solar arrays dark blue with a grid of cells, the antenna white, booms and thruster dark
//! metal (docs/sim-camera.md).

use super::look::{Material, Part, Texture};
use super::{Mesh, Symmetry, SymmetryClass, TargetModel, GREATEST_DIMENSION_M};

/// Names accepted by [`builtin`].
pub const BUILTIN_NAMES: [&str; 3] = ["asymmetric", "one-plane", "two-planes"];

/// Side of one solar cell, model units before scaling (0.1 of 3.4 for `two-planes`: about 6 cm
/// at 2 m).
const CELL: f64 = 0.1;

/// A built-in target by name, or `None`.
pub fn builtin(name: &str) -> Option<TargetModel> {
    if let Some(m) = super::detailed::builtin(name) {
        return Some(m);
    }
    let (symmetry, group, parts) = match name {
        "two-planes" => (SymmetryClass::TwoPlanes, "two-planes:z", parts(true, true, false)),
        "one-plane" => (SymmetryClass::OnePlane, "one-plane", parts(true, false, false)),
        "asymmetric" => (SymmetryClass::None, "none", parts(true, false, true)),
        _ => return None,
    };
    let symmetry_group = Symmetry::parse(group).ok()?;
    let raw = Mesh::new(parts.vertices, parts.faces).ok()?;
    let (lo, hi) = raw.bounds();
    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
    let factor = GREATEST_DIMENSION_M / raw.greatest_dimension();
    let mesh = raw.centered().scaled(factor).ok()?;
    let parts = parts.parts.into_iter().map(|p| p.transformed(centre, factor)).collect();
    Some(TargetModel { name: name.to_string(), symmetry, symmetry_group, mesh, parts })
}

/// The kinds of part a procedural spacecraft is made of, each with its material.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Bus,
    SolarArray,
    Boom,
    Antenna,
    Thruster,
    /// Edge rails of the bus and frames of the solar panels: anodised aluminium.
    Frame,
    /// Hinges and yokes of the arrays: bare metal.
    Hinge,
    /// Star trackers, cameras, horns: black anodised.
    Instrument,
    /// Radiator panels on the bus: white, glossy.
    Radiator,
}

impl Kind {
    pub(super) fn name(self) -> &'static str {
        match self {
            Kind::Bus => "bus",
            Kind::SolarArray => "solar-array",
            Kind::Boom => "boom",
            Kind::Antenna => "antenna",
            Kind::Thruster => "thruster",
            Kind::Frame => "frame",
            Kind::Hinge => "hinge",
            Kind::Instrument => "instrument",
            Kind::Radiator => "radiator",
        }
    }

    pub(super) fn material(self) -> Material {
        let m = |rgba: [f32; 4], specular: f32, shininess: f32, texture: Option<Texture>| {
            Material { name: self.name().to_string(), rgba, specular, shininess, texture }
        };
        match self {
            // Gold multi-layer insulation: saturated yellow-orange, bright tight highlights.
            Kind::Bus => m([0.85, 0.62, 0.18, 1.0], 0.9, 0.7, None),
            // Dark blue cells behind glass, edged by light interconnect lines.
            Kind::SolarArray => m(
                [1.0, 1.0, 1.0, 1.0],
                0.6,
                0.8,
                Some(Texture::CellGrid {
                    cell_rgb: [0.05, 0.09, 0.30],
                    line_rgb: [0.55, 0.57, 0.62],
                }),
            ),
            // White-painted dish: matte.
            Kind::Antenna => m([0.92, 0.92, 0.90, 1.0], 0.2, 0.2, None),
            // Dark metal: grey, fairly shiny.
            Kind::Boom | Kind::Thruster => m([0.22, 0.22, 0.24, 1.0], 0.7, 0.6, None),
            // Clear-anodised aluminium: light grey, soft highlight.
            Kind::Frame => m([0.62, 0.63, 0.66, 1.0], 0.5, 0.4, None),
            // Bare machined metal: bright and sharp.
            Kind::Hinge => m([0.75, 0.74, 0.70, 1.0], 0.9, 0.8, None),
            // Black anodised optics housings and horns.
            Kind::Instrument => m([0.06, 0.06, 0.07, 1.0], 0.3, 0.5, None),
            // White radiator paint (silver-teflon look): bright, glossy.
            Kind::Radiator => m([0.93, 0.94, 0.96, 1.0], 0.6, 0.6, None),
        }
    }
}

/// The merged mesh and the parts, built together.
#[derive(Default)]
pub(super) struct Builder {
    pub(super) vertices: Vec<[f64; 3]>,
    pub(super) faces: Vec<[u32; 3]>,
    pub(super) parts: Vec<Part>,
    /// The symmetry axis the detailed models orient their round parts by (zero: z).
    pub(super) axis: [f64; 3],
}

impl Builder {
    /// The part of `kind`, created on first use.
    pub(super) fn part(&mut self, kind: Kind) -> &mut Part {
        let i = match self.parts.iter().position(|p| p.name == kind.name()) {
            Some(i) => i,
            None => {
                self.parts.push(Part {
                    name: kind.name().to_string(),
                    vertices: Vec::new(),
                    faces: Vec::new(),
                    texcoords: Vec::new(),
                    material: kind.material(),
                });
                self.parts.len() - 1
            }
        };
        &mut self.parts[i]
    }

    /// Axis-aligned box with outward-facing (counter-clockwise seen from outside) triangles.
    /// In the part, each face has its own four corners (flat shading) and texture coordinates
    /// of one unit per [`CELL`], from the face's lower corner.
    fn add_box(&mut self, kind: Kind, c: [f64; 3], h: [f64; 3]) {
        let base = self.vertices.len() as u32;
        let corner = |i: u32| {
            let sx = if i & 1 == 0 { -1.0 } else { 1.0 };
            let sy = if i & 2 == 0 { -1.0 } else { 1.0 };
            let sz = if i & 4 == 0 { -1.0 } else { 1.0 };
            [c[0] + sx * h[0], c[1] + sy * h[1], c[2] + sz * h[2]]
        };
        for i in 0..8u32 {
            self.vertices.push(corner(i));
        }
        // Quads as (a, b, c, d) counter-clockwise from outside, with the axis they face.
        let quads = [
            ([0, 2, 3, 1], 2), // -z
            ([4, 5, 7, 6], 2), // +z
            ([0, 1, 5, 4], 1), // -y
            ([2, 6, 7, 3], 1), // +y
            ([0, 4, 6, 2], 0), // -x
            ([1, 3, 7, 5], 0), // +x
        ];
        for (q, _) in quads {
            self.faces.push([base + q[0], base + q[1], base + q[2]]);
            self.faces.push([base + q[0], base + q[2], base + q[3]]);
        }
        let part = self.part(kind);
        for (q, axis) in quads {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let pb = part.vertices.len() as u32;
            for i in q {
                let p = corner(i);
                part.vertices.push(p);
                let uv = |k: usize| ((p[k] - (c[k] - h[k])) / CELL) as f32;
                part.texcoords.push([uv(a), uv(b)]);
            }
            part.faces.push([pb, pb + 1, pb + 2]);
            part.faces.push([pb, pb + 2, pb + 3]);
        }
    }

    /// A dish: a closed cone opening towards +z, apex at `apex`, rim radius `r` at height `h`.
    fn add_dish(&mut self, kind: Kind, apex: [f64; 3], r: f64, h: f64, n: u32) {
        let base = self.vertices.len() as u32;
        let first_face = self.faces.len();
        self.vertices.push(apex);
        let rim_centre = [apex[0], apex[1], apex[2] + h];
        self.vertices.push(rim_centre);
        for i in 0..n {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            self.vertices.push([apex[0] + r * a.cos(), apex[1] + r * a.sin(), apex[2] + h]);
        }
        for i in 0..n {
            let p = base + 2 + i;
            let q = base + 2 + (i + 1) % n;
            // Side (outward, facing down-and-out) and rim disc (facing +z).
            self.faces.push([base, q, p]);
            self.faces.push([base + 1, p, q]);
        }
        let vertices = self.vertices[base as usize..].to_vec();
        let faces: Vec<[u32; 3]> =
            self.faces[first_face..].iter().map(|f| f.map(|i| i - base)).collect();
        let part = self.part(kind);
        // A part with texture coordinates has them for every vertex; the dish has none, and
        // shares no part with a box.
        let pb = part.vertices.len() as u32;
        part.vertices.extend(vertices);
        part.faces.extend(faces.into_iter().map(|f| f.map(|i| i + pb)));
    }
}

/// Bus 0.8 x 0.8 x 1.0, wing(s) 1.1 x 0.6 x 0.04 on a boom, dish on top (before scaling).
fn parts(wing_pos_x: bool, wing_neg_x: bool, asymmetric: bool) -> Builder {
    let mut b = Builder::default();
    b.add_box(Kind::Bus, [0.0, 0.0, 0.0], [0.4, 0.4, 0.5]);
    for (on, s) in [(wing_pos_x, 1.0), (wing_neg_x, -1.0)] {
        if on {
            b.add_box(Kind::Boom, [s * 0.5, 0.0, 0.0], [0.1, 0.03, 0.03]);
            b.add_box(Kind::SolarArray, [s * 1.15, 0.0, 0.0], [0.55, 0.3, 0.02]);
        }
    }
    if asymmetric {
        b.add_dish(Kind::Antenna, [-0.12, 0.18, 0.5], 0.2, 0.15, 16);
        b.add_box(Kind::Thruster, [0.15, -0.2, -0.58], [0.1, 0.1, 0.08]);
    } else {
        b.add_dish(Kind::Antenna, [0.0, 0.0, 0.5], 0.25, 0.18, 16);
    }
    b
}
