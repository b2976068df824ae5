//! Targets keep their materials: the built-ins' parts, an OBJ's MTL materials and PNG texture,
//! STL's one plain material, and a clear error naming the file for every way an OBJ/MTL can be
//! broken.
#![allow(clippy::unwrap_used)]

use hitl_perception::models::{load_model_file, Texture};
use hitl_perception::{PerceptionError, TargetModel};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/textured_cube").join(name)
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Area-weighted sum over a mesh's triangles, to compare surfaces.
fn area(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> f64 {
    faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| vertices[i as usize]);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n =
                [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        })
        .sum()
}

#[test]
fn built_ins_have_their_parts_in_distinct_materials_on_the_same_surface() {
    for name in ["asymmetric", "one-plane", "two-planes"] {
        let m = TargetModel::from_spec(name).unwrap();
        let names: Vec<&str> = m.parts.iter().map(|p| p.name.as_str()).collect();
        assert!(names.contains(&"bus") && names.contains(&"solar-array"), "{name}: {names:?}");
        assert!(names.contains(&"antenna"), "{name}: {names:?}");
        assert_eq!(names.contains(&"thruster"), name == "asymmetric", "{name}: {names:?}");
        // The parts cover the merged mesh's surface, in the same frame and scale.
        let parts: f64 = m.parts.iter().map(|p| area(&p.vertices, &p.faces)).sum();
        let whole = m.mesh.total_area();
        assert!((parts - whole).abs() < 1e-9 * whole, "{name}: parts {parts} vs mesh {whole}");
        let colour = |n: &str| m.parts.iter().find(|p| p.name == n).unwrap().material.clone();
        let (bus, array) = (colour("bus"), colour("solar-array"));
        assert!(bus.rgba[0] > bus.rgba[2] + 0.5, "gold bus {:?}", bus.rgba);
        assert!(bus.specular > 0.5, "shiny foil");
        match array.texture {
            Some(Texture::CellGrid { cell_rgb, .. }) => assert!(cell_rgb[2] > cell_rgb[0] + 0.2),
            other => panic!("{name}: array texture {other:?}"),
        }
        let array_part = m.parts.iter().find(|p| p.name == "solar-array").unwrap();
        assert_eq!(array_part.texcoords.len(), array_part.vertices.len());
    }
}

#[test]
fn an_obj_keeps_its_mtl_material_and_png_texture() {
    let (mesh, parts) = load_model_file(&data("cube.obj")).unwrap();
    assert_eq!(mesh.faces().len(), 12);
    assert_eq!(parts.len(), 1);
    let p = &parts[0];
    assert_eq!(p.name, "quadrants");
    assert_eq!(p.material.rgba, [1.0, 1.0, 1.0, 1.0]);
    assert!((p.material.specular - 0.1).abs() < 1e-6);
    assert!((p.material.shininess - 10.0 / 128.0).abs() < 1e-6);
    match &p.material.texture {
        Some(Texture::Png(path)) => {
            assert!(path.is_absolute() && path.ends_with("quadrants.png"), "{}", path.display())
        }
        other => panic!("texture {other:?}"),
    }
    assert_eq!(p.texcoords.len(), p.vertices.len());
    // Scaled with the mesh by from_spec.
    let m = TargetModel::from_spec(data("cube.obj").to_str().unwrap()).unwrap();
    assert!((area(&m.parts[0].vertices, &m.parts[0].faces) - m.mesh.total_area()).abs() < 1e-9);
}

#[test]
fn an_stl_is_one_plain_part() {
    let dir = tempfile::tempdir().unwrap();
    let stl = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 3 0\nendloop\nendfacet\nendsolid t\n";
    let p = write(dir.path(), "tri.stl", stl.as_bytes());
    let (_, parts) = load_model_file(&p).unwrap();
    assert_eq!(parts.len(), 1);
    assert!(parts[0].material.texture.is_none() && parts[0].texcoords.is_empty());
}

#[test]
fn broken_objs_and_mtls_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let png = std::fs::read(data("quadrants.png")).unwrap();
    write(d, "q.png", &png);
    write(d, "not-png.png", b"GIF89a not a png");
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n";
    let faces = "f 1/1 2/2 3/3\nf 1/1 2/2 4/4\n";
    let obj = |name: &str, head: &str, body: &str| -> PathBuf {
        write(d, name, format!("{head}\n{tri}{body}").as_bytes())
    };
    write(d, "good.mtl", b"newmtl m\nKd 1 1 1\nmap_Kd q.png\n");
    write(d, "lost_tex.mtl", b"newmtl m\nKd 1 1 1\nmap_Kd nowhere.png\n");
    write(d, "gif.mtl", b"newmtl m\nKd 1 1 1\nmap_Kd not-png.png\n");
    let cases: Vec<(PathBuf, &str)> = vec![
        (obj("no_mtl.obj", "mtllib missing.mtl", &format!("usemtl m\n{faces}")), "missing.mtl"),
        (obj("lost_tex.obj", "mtllib lost_tex.mtl", &format!("usemtl m\n{faces}")), "nowhere.png"),
        (obj("gif.obj", "mtllib gif.mtl", &format!("usemtl m\n{faces}")), "not a PNG"),
        (obj("unknown.obj", "mtllib good.mtl", &format!("usemtl other\n{faces}")), "\"other\""),
        (obj("nolib.obj", "", &format!("usemtl m\n{faces}")), "mtllib"),
        (
            obj("no_vt.obj", "mtllib good.mtl", "usemtl m\nf 1 2 3\nf 1 2 4\n"),
            "texture coordinates",
        ),
        (obj("bad_index.obj", "mtllib good.mtl", "usemtl m\nf 1/1 2/2 9/3\n"), ""),
        (obj("junk.obj", "", "f x y z\n"), ""),
    ];
    for (p, needle) in cases {
        let e = load_model_file(&p).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, PerceptionError::BadModel { .. }), "{msg}");
        assert!(msg.contains(p.file_name().unwrap().to_str().unwrap()), "{msg}");
        assert!(msg.contains(needle), "{msg} lacks {needle:?}");
        // The run's loader says the same.
        assert!(TargetModel::from_spec(p.to_str().unwrap()).is_err(), "{msg}");
    }
    // The good one loads.
    let (_, parts) =
        load_model_file(&obj("good.obj", "mtllib good.mtl", &format!("usemtl m\n{faces}")))
            .unwrap();
    assert!(matches!(parts[0].material.texture, Some(Texture::Png(_))));
}
