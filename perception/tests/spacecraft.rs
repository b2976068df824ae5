//! The detailed built-in spacecraft (the paper's models 1-5): their sizes, face counts, parts and
//! materials, and that each declared symmetry group is exactly right: every declared rotation maps
//! the vertices onto themselves, and the mirror planes through the axes are the ones the class
//! names (so no undeclared half turn hides in a model either).
#![allow(clippy::unwrap_used)]

use hitl_perception::models::{SymmetryClass, SPACECRAFT_NAMES};
use hitl_perception::TargetModel;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Point3, Vector3};

/// Does `map` send every vertex within 1e-9 m of a vertex?
fn invariant(m: &TargetModel, map: impl Fn(Vector3<f64>) -> Vector3<f64>) -> bool {
    let v: Vec<[f64; 3]> = m.mesh.vertices().to_vec();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&v).unwrap();
    v.iter().all(|p| {
        let q = map(Vector3::from(*p));
        let r = tree.query(&[q.x, q.y, q.z]).nearest_one::<SquaredEuclidean<f64>>().execute();
        r.distance < 1e-18
    })
}

#[test]
fn five_detailed_spacecraft_in_the_paper_s_symmetry_classes() {
    let expect = [
        ("sat1-none", SymmetryClass::None, [false, false, false], "none"),
        ("sat2-one-plane", SymmetryClass::OnePlane, [false, true, false], "one-plane"),
        ("sat3-two-planes", SymmetryClass::TwoPlanes, [true, true, false], "two-planes:z"),
        ("sat4-two-planes-slender", SymmetryClass::TwoPlanes, [true, true, false], "two-planes:z"),
        ("sat5-two-planes-y", SymmetryClass::TwoPlanes, [true, false, true], "two-planes:y"),
    ];
    assert_eq!(SPACECRAFT_NAMES.len(), 5);
    for (name, class, planes, group) in expect {
        let m = TargetModel::from_spec(name).unwrap();
        let faces = m.mesh.faces().len();
        eprintln!("{name}: {faces} faces, {} parts", m.parts.len());
        assert!((5_000..=60_000).contains(&faces), "{name}: {faces} faces");
        assert_eq!(m.symmetry, class, "{name}");
        assert_eq!(m.symmetry_group.spec, group, "{name}");
        assert!((m.greatest_dimension_m() - 2.0).abs() < 1e-9, "{name}");
        // Every triangle is in exactly one part, and the parts name their materials.
        assert_eq!(m.parts.iter().map(|p| p.faces.len()).sum::<usize>(), faces, "{name}");
        let kinds: Vec<&str> = m.parts.iter().map(|p| p.name.as_str()).collect();
        for k in ["bus", "frame", "solar-array", "hinge", "boom", "antenna", "thruster"] {
            assert!(kinds.contains(&k), "{name} has no {k}: {kinds:?}");
        }
        for p in &m.parts {
            assert_eq!(p.material.name, p.name);
            assert_eq!(p.texcoords.len(), p.vertices.len(), "{name} {}", p.name);
        }
        // Mirror planes x = 0, y = 0, z = 0: exactly those the class names.
        for (axis, want) in planes.iter().enumerate() {
            let mirror = |mut p: Vector3<f64>| {
                p[axis] = -p[axis];
                p
            };
            assert_eq!(invariant(&m, mirror), *want, "{name}: mirror plane {axis} = 0");
        }
        // The declared rotations are symmetries; no other half turn about an axis is.
        for r in &m.symmetry_group.rotations {
            let c = m.symmetry_group.point;
            assert!(
                invariant(&m, |p| (r * Point3::from(p - c.coords)).coords + c.coords),
                "{name}"
            );
        }
        for axis in [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()] {
            let turn = nalgebra::UnitQuaternion::from_axis_angle(&axis, std::f64::consts::PI);
            let declared = m.symmetry_group.rotations.iter().any(|r| r.angle_to(&turn) < 1e-9);
            assert_eq!(invariant(&m, |p| turn * p), declared, "{name}: half turn about {axis:?}");
        }
    }
}

#[test]
fn the_simple_targets_keep_their_names_and_meshes() {
    for (name, faces) in [("asymmetric", 80), ("one-plane", 68), ("two-planes", 92)] {
        assert_eq!(TargetModel::from_spec(name).unwrap().mesh.faces().len(), faces, "{name}");
    }
}
