//! A validated indexed triangle mesh.

use crate::PerceptionError;

/// An indexed triangle mesh, metres, body frame. Constructed only through [`Mesh::new`], which
/// checks indices, finiteness and that the mesh has a non-zero extent.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
}

/// Refuse meshes above this many faces (a bound on memory and sampling time).
pub const MAX_FACES: usize = 5_000_000;

impl Mesh {
    pub fn new(vertices: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Result<Mesh, PerceptionError> {
        if vertices.is_empty() || faces.is_empty() {
            return Err(PerceptionError::BadMesh(format!(
                "needs vertices and triangles, has {} vertices and {} triangles",
                vertices.len(),
                faces.len()
            )));
        }
        if faces.len() > MAX_FACES {
            return Err(PerceptionError::BadMesh(format!(
                "{} triangles is more than the limit of {MAX_FACES}",
                faces.len()
            )));
        }
        if let Some(i) = vertices.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
            return Err(PerceptionError::BadMesh(format!("vertex {i} is not finite")));
        }
        let n = vertices.len() as u32;
        if let Some(i) = faces.iter().position(|f| f.iter().any(|&v| v >= n)) {
            return Err(PerceptionError::BadMesh(format!(
                "triangle {i} indexes a vertex beyond the {n} vertices"
            )));
        }
        let m = Mesh { vertices, faces };
        if m.total_area() <= 0.0 || m.greatest_dimension() <= 0.0 {
            return Err(PerceptionError::BadMesh(
                "all triangles are degenerate (zero area)".into(),
            ));
        }
        Ok(m)
    }

    pub fn vertices(&self) -> &[[f64; 3]] {
        &self.vertices
    }

    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }

    /// Axis-aligned bounding box (min, max).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        (lo, hi)
    }

    /// Greatest bounding-box edge, metres.
    pub fn greatest_dimension(&self) -> f64 {
        let (lo, hi) = self.bounds();
        (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max)
    }

    /// Length of the bounding-box diagonal, metres.
    pub fn diameter(&self) -> f64 {
        let (lo, hi) = self.bounds();
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
    }

    /// Corners of triangle `i`.
    pub fn triangle(&self, i: usize) -> [[f64; 3]; 3] {
        let f = self.faces[i];
        [self.vertices[f[0] as usize], self.vertices[f[1] as usize], self.vertices[f[2] as usize]]
    }

    pub fn total_area(&self) -> f64 {
        (0..self.faces.len()).map(|i| triangle_area(&self.triangle(i))).sum()
    }

    /// The mesh translated so its bounding-box midpoint is the origin.
    pub fn centered(mut self) -> Mesh {
        let (lo, hi) = self.bounds();
        let c = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
        for v in &mut self.vertices {
            for k in 0..3 {
                v[k] -= c[k];
            }
        }
        self
    }

    /// The mesh scaled uniformly about the origin by `factor` (> 0).
    pub fn scaled(&self, factor: f64) -> Result<Mesh, PerceptionError> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(PerceptionError::BadMesh(format!(
                "scale factor must be positive, got {factor}"
            )));
        }
        let vertices =
            self.vertices.iter().map(|v| [v[0] * factor, v[1] * factor, v[2] * factor]).collect();
        Ok(Mesh { vertices, faces: self.faces.clone() })
    }

    /// The mesh scaled so its greatest dimension is `d` metres.
    pub fn scaled_to_greatest_dimension(&self, d: f64) -> Result<Mesh, PerceptionError> {
        self.scaled(d / self.greatest_dimension())
    }

    /// Single-precision copy for renderers.
    pub fn to_f32(&self) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            self.vertices.iter().map(|v| [v[0] as f32, v[1] as f32, v[2] as f32]).collect(),
            self.faces.clone(),
        )
    }
}

/// Area of a triangle.
pub fn triangle_area(t: &[[f64; 3]; 3]) -> f64 {
    0.5 * triangle_cross(t).iter().map(|c| c * c).sum::<f64>().sqrt()
}

/// `(b - a) x (c - a)`: twice the area times the unit normal (right-handed winding).
pub fn triangle_cross(t: &[[f64; 3]; 3]) -> [f64; 3] {
    let u = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
    let v = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
    [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
}
