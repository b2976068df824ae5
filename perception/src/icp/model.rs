//! The tracker's view of the target: an area-weighted point sample of the mesh surface with face
//! normals, in a kd-tree (`kiddo`) for nearest-neighbour correspondences.

use crate::models::mesh::{triangle_area, triangle_cross};
use crate::models::Mesh;
use crate::PerceptionError;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Vector3;
use std::num::NonZero;

/// Surface samples of the target, body frame.
pub struct ModelCloud {
    pub points: Vec<Vector3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    tree: ImmutableKdTree<f64, 3>,
    /// Bounding-box diagonal, metres.
    pub diameter: f64,
    /// Mean distance between neighbouring samples, metres.
    pub spacing: f64,
    /// Normals point out of the body (closed, consistently wound mesh): visibility can use them.
    pub oriented: bool,
}

/// A small deterministic generator (xorshift64*), so samples never change between runs.
struct Rng(u64);
impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

impl ModelCloud {
    /// Samples `n` points over the surface (stratified by area).
    pub fn from_mesh(mesh: &Mesh, n: usize) -> Result<ModelCloud, PerceptionError> {
        let n = n.max(16);
        let nf = mesh.faces().len();
        let mut cum = Vec::with_capacity(nf);
        let mut total = 0.0;
        let mut signed_volume = 0.0;
        for i in 0..nf {
            let t = mesh.triangle(i);
            total += triangle_area(&t);
            cum.push(total);
            let c = triangle_cross(&t);
            signed_volume += (c[0] * t[0][0] + c[1] * t[0][1] + c[2] * t[0][2]) / 6.0;
        }
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        let mut points = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        for i in 0..n {
            let target = (i as f64 + rng.next_f64()) / n as f64 * total;
            let f = cum.partition_point(|&c| c < target).min(nf - 1);
            let t = mesh.triangle(f);
            let c = triangle_cross(&t);
            let cn = Vector3::new(c[0], c[1], c[2]);
            if cn.norm() == 0.0 {
                continue;
            }
            let (r1, r2) = (rng.next_f64().sqrt(), rng.next_f64());
            let (a, b, cc) = (1.0 - r1, r1 * (1.0 - r2), r1 * r2);
            let p = Vector3::new(
                a * t[0][0] + b * t[1][0] + cc * t[2][0],
                a * t[0][1] + b * t[1][1] + cc * t[2][1],
                a * t[0][2] + b * t[1][2] + cc * t[2][2],
            );
            points.push(p);
            normals.push(cn.normalize());
        }
        let arr: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = ImmutableKdTree::new_from_slice(&arr)
            .map_err(|e| PerceptionError::BadMesh(format!("cannot index samples: {e:?}")))?;
        Ok(ModelCloud {
            spacing: (total / points.len() as f64).sqrt(),
            points,
            normals,
            tree,
            diameter: mesh.diameter(),
            oriented: signed_volume > 0.0,
        })
    }

    /// The same samples scaled by `f` about the body origin.
    pub fn scaled(&self, f: f64) -> Result<ModelCloud, PerceptionError> {
        let points: Vec<Vector3<f64>> = self.points.iter().map(|p| p * f).collect();
        let arr: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = ImmutableKdTree::new_from_slice(&arr)
            .map_err(|e| PerceptionError::BadMesh(format!("cannot index samples: {e:?}")))?;
        Ok(ModelCloud {
            points,
            normals: self.normals.clone(),
            tree,
            diameter: self.diameter * f,
            spacing: self.spacing * f,
            oriented: self.oriented,
        })
    }

    /// Nearest sample to `p` (body frame): index and squared distance.
    pub fn nearest(&self, p: &Vector3<f64>) -> (usize, f64) {
        let r = self.tree.query(&[p.x, p.y, p.z]).nearest_one::<SquaredEuclidean<f64>>().execute();
        (r.item as usize, r.distance)
    }

    /// Nearest sample to `p` whose normal faces `view` (body-frame direction from the point towards
    /// the camera), among the `k` nearest; falls back to the nearest when normals are not oriented.
    pub fn nearest_facing(&self, p: &Vector3<f64>, view: &Vector3<f64>, k: usize) -> (usize, f64) {
        if !self.oriented {
            return self.nearest(p);
        }
        let first = self.nearest(p);
        if self.normals[first.0].dot(view) > 0.0 {
            return first;
        }
        let Some(k) = NonZero::new(k) else {
            return first;
        };
        let found =
            self.tree.query(&[p.x, p.y, p.z]).nearest_n::<SquaredEuclidean<f64>>(k).execute();
        for r in &found {
            if self.normals[r.item as usize].dot(view) > 0.0 {
                return (r.item as usize, r.distance);
            }
        }
        found.first().map(|r| (r.item as usize, r.distance)).unwrap_or_else(|| self.nearest(p))
    }
}
