//! The project's own procedural spacecraft, one per symmetry class of the paper, each centred and
//! scaled so its greatest dimension is 2 m:
//! - `two-planes`: box bus, two equal solar wings on a boom along +-x, antenna dish on +z
//!   (mirror planes x = 0 and y = 0);
//! - `one-plane`: the same bus and dish with a single wing on +x (mirror plane y = 0);
//! - `asymmetric`: one wing on +x, the dish off-centre on +z and a thruster block off-centre on -z
//!   (no mirror plane).

use super::{Mesh, SymmetryClass, TargetModel, GREATEST_DIMENSION_M};

/// Names accepted by [`builtin`].
pub const BUILTIN_NAMES: [&str; 3] = ["asymmetric", "one-plane", "two-planes"];

/// A built-in target by name, or `None`.
pub fn builtin(name: &str) -> Option<TargetModel> {
    let (symmetry, parts) = match name {
        "two-planes" => (SymmetryClass::TwoPlanes, parts(true, true, false)),
        "one-plane" => (SymmetryClass::OnePlane, parts(true, false, false)),
        "asymmetric" => (SymmetryClass::None, parts(true, false, true)),
        _ => return None,
    };
    let mesh = Mesh::new(parts.vertices, parts.faces)
        .and_then(|m| m.centered().scaled_to_greatest_dimension(GREATEST_DIMENSION_M))
        .ok()?;
    Some(TargetModel { name: name.to_string(), symmetry, mesh })
}

#[derive(Default)]
struct Builder {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
}

impl Builder {
    /// Axis-aligned box with outward-facing (counter-clockwise seen from outside) triangles.
    fn add_box(&mut self, c: [f64; 3], h: [f64; 3]) {
        let base = self.vertices.len() as u32;
        for i in 0..8u32 {
            let sx = if i & 1 == 0 { -1.0 } else { 1.0 };
            let sy = if i & 2 == 0 { -1.0 } else { 1.0 };
            let sz = if i & 4 == 0 { -1.0 } else { 1.0 };
            self.vertices.push([c[0] + sx * h[0], c[1] + sy * h[1], c[2] + sz * h[2]]);
        }
        // Quads as (a, b, c, d) counter-clockwise from outside.
        let quads = [
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
        ];
        for q in quads {
            self.faces.push([base + q[0], base + q[1], base + q[2]]);
            self.faces.push([base + q[0], base + q[2], base + q[3]]);
        }
    }

    /// A dish: a closed cone opening towards +z, apex at `apex`, rim radius `r` at height `h`.
    fn add_dish(&mut self, apex: [f64; 3], r: f64, h: f64, n: u32) {
        let base = self.vertices.len() as u32;
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
    }
}

/// Bus 0.8 x 0.8 x 1.0, wing(s) 1.1 x 0.6 x 0.04 on a boom, dish on top (before scaling).
fn parts(wing_pos_x: bool, wing_neg_x: bool, asymmetric: bool) -> Builder {
    let mut b = Builder::default();
    b.add_box([0.0, 0.0, 0.0], [0.4, 0.4, 0.5]);
    for (on, s) in [(wing_pos_x, 1.0), (wing_neg_x, -1.0)] {
        if on {
            b.add_box([s * 0.5, 0.0, 0.0], [0.1, 0.03, 0.03]);
            b.add_box([s * 1.15, 0.0, 0.0], [0.55, 0.3, 0.02]);
        }
    }
    if asymmetric {
        b.add_dish([-0.12, 0.18, 0.5], 0.2, 0.15, 16);
        b.add_box([0.15, -0.2, -0.58], [0.1, 0.1, 0.08]);
    } else {
        b.add_dish([0.0, 0.0, 0.5], 0.25, 0.18, 16);
    }
    b
}
