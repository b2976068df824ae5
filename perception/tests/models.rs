//! Target models: procedural spacecraft (symmetry classes, 2 m) and OBJ/STL loading.
#![allow(clippy::unwrap_used)]

use hitl_perception::models::{load_mesh_file, SymmetryClass, BUILTIN_NAMES};
use hitl_perception::{PerceptionError, TargetModel};
use std::io::Write;

/// Is the vertex set mirror-symmetric about the plane `axis = 0`?
fn mirror_symmetric(m: &TargetModel, axis: usize) -> bool {
    let v = m.mesh.vertices();
    v.iter().all(|p| {
        let mut q = *p;
        q[axis] = -q[axis];
        v.iter().any(|r| (0..3).all(|k| (r[k] - q[k]).abs() < 1e-9))
    })
}

#[test]
fn builtins_cover_the_symmetry_classes_at_two_metres() {
    let expect = [
        ("asymmetric", SymmetryClass::None, [false, false, false]),
        ("one-plane", SymmetryClass::OnePlane, [false, true, false]),
        ("two-planes", SymmetryClass::TwoPlanes, [true, true, false]),
    ];
    assert_eq!(BUILTIN_NAMES.len(), expect.len());
    for (name, class, planes) in expect {
        let m = TargetModel::from_spec(name).unwrap();
        assert_eq!(m.symmetry, class);
        assert!((m.greatest_dimension_m() - 2.0).abs() < 1e-9, "{name}");
        let (lo, hi) = m.mesh.bounds();
        for k in 0..3 {
            assert!((lo[k] + hi[k]).abs() < 1e-9, "{name} not centred on axis {k}");
        }
        for (axis, want) in planes.iter().enumerate() {
            assert_eq!(mirror_symmetric(&m, axis), *want, "{name}: mirror plane on axis {axis}");
        }
        let (v, f) = m.vertices_faces();
        assert_eq!(v.len(), m.mesh.vertices().len());
        assert_eq!(f.len(), m.mesh.faces().len());
        let lab = m.lab_mesh(0.05).unwrap();
        assert!((lab.greatest_dimension() - 0.1).abs() < 1e-9);
    }
}

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.path().join(name);
    std::fs::File::create(&p).unwrap().write_all(bytes).unwrap();
    p
}

#[test]
fn loads_obj_and_ascii_stl_and_normalises_to_two_metres() {
    let dir = tempfile::tempdir().unwrap();
    let obj = "v 0 0 0\nv 4 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    let p = write(&dir, "tet.obj", obj.as_bytes());
    let raw = load_mesh_file(&p).unwrap();
    assert_eq!((raw.vertices().len(), raw.faces().len()), (4, 4));
    let m = TargetModel::from_spec(p.to_str().unwrap()).unwrap();
    assert_eq!(m.name, "tet");
    assert!((m.greatest_dimension_m() - 2.0).abs() < 1e-9);

    let stl = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 3 0\nendloop\nendfacet\nendsolid t\n";
    let p = write(&dir, "tri.stl", stl.as_bytes());
    let m = load_mesh_file(&p).unwrap();
    assert_eq!(m.faces().len(), 1);
    assert!((m.greatest_dimension() - 3.0).abs() < 1e-6);
}

#[test]
fn bad_files_are_errors_that_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(std::path::PathBuf, &str)> = vec![
        (write(&dir, "empty.obj", b""), "no triangles"),
        (write(&dir, "badidx.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"), ""),
        (write(&dir, "flat.obj", b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n"), "degenerate"),
        (write(&dir, "nan.obj", b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), ""),
        (write(&dir, "junk.stl", &[0xffu8; 50]), "STL"),
        (write(&dir, "mesh.ply", b"ply\n"), "unsupported"),
        (dir.path().join("missing.stl"), "cannot open"),
    ];
    for (p, needle) in cases {
        let e = load_mesh_file(&p).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, PerceptionError::BadModel { .. }), "{msg}");
        assert!(msg.contains(p.file_name().unwrap().to_str().unwrap()), "{msg}");
        assert!(msg.contains(needle), "{msg} lacks {needle:?}");
    }
    assert!(TargetModel::from_spec("no-such-target").is_err());
}
