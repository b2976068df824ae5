//! Capsules (swept spheres) and the distances between them, for clearance checks.
//!
//! Every part of the arm, the camera and every keep-out volume is a capsule: a segment `a`-`b`
//! with a radius. A sphere is a capsule with `a == b`. Distances are between surfaces, so a
//! negative distance means the two volumes overlap.

use hitl_hal::Pose;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// A segment swept by a sphere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Capsule {
    pub a: Point3<f64>,
    pub b: Point3<f64>,
    pub radius: f64,
}

impl Capsule {
    pub fn new(a: Point3<f64>, b: Point3<f64>, radius: f64) -> Self {
        Self { a, b, radius }
    }

    pub fn sphere(centre: Point3<f64>, radius: f64) -> Self {
        Self { a: centre, b: centre, radius }
    }

    /// This capsule moved by `pose`.
    pub fn transformed(&self, pose: &Pose) -> Self {
        Self { a: pose * self.a, b: pose * self.b, radius: self.radius }
    }

    /// Surface-to-surface distance to another capsule (negative when they overlap).
    pub fn distance_to(&self, other: &Capsule) -> f64 {
        segment_segment_distance(&self.a, &self.b, &other.a, &other.b) - self.radius - other.radius
    }

    /// Surface distance to a point (negative inside).
    pub fn distance_to_point(&self, p: &Point3<f64>) -> f64 {
        point_segment_distance(p, &self.a, &self.b) - self.radius
    }

    /// Clearance of the capsule inside an axis-aligned box `[lo, hi]`, per face:
    /// `[x-, x+, y-, y+, z-, z+]`, each the distance from the capsule's surface to that face
    /// (negative when the capsule crosses it). A segment's extreme along an axis is an endpoint.
    pub fn box_clearances(&self, lo: &Point3<f64>, hi: &Point3<f64>) -> [f64; 6] {
        let mut out = [0.0; 6];
        for axis in 0..3 {
            let min = self.a[axis].min(self.b[axis]);
            let max = self.a[axis].max(self.b[axis]);
            out[2 * axis] = min - lo[axis] - self.radius;
            out[2 * axis + 1] = hi[axis] - max - self.radius;
        }
        out
    }
}

/// Distance from point `p` to the segment `a`-`b`.
pub fn point_segment_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 { ((p - a).dot(&ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p - (a + ab * t)).norm()
}

/// Closest distance between segments `p1`-`q1` and `p2`-`q2` (Ericson, Real-Time Collision
/// Detection, 5.1.9), robust to degenerate (point) segments and parallel segments.
pub fn segment_segment_distance(
    p1: &Point3<f64>,
    q1: &Point3<f64>,
    p2: &Point3<f64>,
    q2: &Point3<f64>,
) -> f64 {
    const EPS: f64 = 1e-12;
    let d1: Vector3<f64> = q1 - p1;
    let d2: Vector3<f64> = q2 - p2;
    let r: Vector3<f64> = p1 - p2;
    let a = d1.norm_squared();
    let e = d2.norm_squared();
    let f = d2.dot(&r);
    let (s, t);
    if a <= EPS && e <= EPS {
        return r.norm();
    }
    if a <= EPS {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(&r);
        if e <= EPS {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > EPS { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    let c1 = p1 + d1 * s;
    let c2 = p2 + d2 * t;
    (c1 - c2).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64, z: f64) -> Point3<f64> {
        Point3::new(x, y, z)
    }

    #[test]
    fn crossing_segments_are_apart_by_their_offset() {
        let d = segment_segment_distance(
            &p(-1., 0., 0.),
            &p(1., 0., 0.),
            &p(0., -1., 0.5),
            &p(0., 1., 0.5),
        );
        assert!((d - 0.5).abs() < 1e-12);
    }

    #[test]
    fn parallel_segments_and_points() {
        let d = segment_segment_distance(
            &p(0., 0., 0.),
            &p(1., 0., 0.),
            &p(0.5, 2., 0.),
            &p(3., 2., 0.),
        );
        assert!((d - 2.0).abs() < 1e-12);
        let d = segment_segment_distance(
            &p(0., 0., 0.),
            &p(0., 0., 0.),
            &p(3., 4., 0.),
            &p(3., 4., 0.),
        );
        assert!((d - 5.0).abs() < 1e-12);
        let d = segment_segment_distance(
            &p(2., 0., 0.),
            &p(3., 0., 0.),
            &p(0., 0., 0.),
            &p(1., 0., 0.),
        );
        assert!((d - 1.0).abs() < 1e-12);
    }

    #[test]
    fn capsule_overlap_is_negative_and_box_faces_are_per_axis() {
        let c1 = Capsule::new(p(0., 0., 0.), p(1., 0., 0.), 0.2);
        let c2 = Capsule::sphere(p(0.5, 0.3, 0.), 0.2);
        assert!((c1.distance_to(&c2) + 0.1).abs() < 1e-12);
        let faces = c1.box_clearances(&p(-0.5, -1., -1.), &p(2., 1., 1.));
        let want = [0.3, 0.8, 0.8, 0.8, 0.8, 0.8];
        for (got, want) in faces.iter().zip(want) {
            assert!((got - want).abs() < 1e-12, "{faces:?}");
        }
    }
}
