//! Loading the user's target meshes: Wavefront OBJ (`tobj`) and STL, ASCII or binary (`stl_io`).

use super::Mesh;
use crate::PerceptionError;
use std::path::Path;

/// Loads an `.obj` or `.stl` file as one mesh (all objects of an OBJ merged), in the file's units.
pub fn load_mesh_file(path: &Path) -> Result<Mesh, PerceptionError> {
    let bad = |reason: String| PerceptionError::BadModel { path: path.to_path_buf(), reason };
    let ext =
        path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let (vertices, faces) = match ext.as_str() {
        "obj" => load_obj(path).map_err(bad)?,
        "stl" => load_stl(path).map_err(bad)?,
        other => {
            return Err(bad(format!("unsupported mesh format {other:?} (expected .obj or .stl)")))
        }
    };
    Mesh::new(vertices, faces).map_err(|e| bad(e.to_string()))
}

type Raw = (Vec<[f64; 3]>, Vec<[u32; 3]>);

fn load_obj(path: &Path) -> Result<Raw, String> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _materials) =
        tobj::load_obj(path, &opts).map_err(|e| format!("cannot read OBJ: {e}"))?;
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    for m in &models {
        let mesh = &m.mesh;
        if mesh.positions.len() % 3 != 0 || mesh.indices.len() % 3 != 0 {
            return Err(format!("object {:?} has a truncated position or face list", m.name));
        }
        let base = u32::try_from(vertices.len()).map_err(|_| "too many vertices".to_string())?;
        vertices.extend(
            mesh.positions.chunks_exact(3).map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
        );
        let n = (mesh.positions.len() / 3) as u32;
        for f in mesh.indices.chunks_exact(3) {
            if f.iter().any(|&i| i >= n) {
                return Err(format!("object {:?} has a face index beyond its vertices", m.name));
            }
            faces.push([base + f[0], base + f[1], base + f[2]]);
        }
    }
    if faces.is_empty() {
        return Err("no triangles found (an OBJ needs `v` and `f` lines)".into());
    }
    Ok((vertices, faces))
}

fn load_stl(path: &Path) -> Result<Raw, String> {
    let mut file = std::fs::File::open(path).map_err(|e| format!("cannot open: {e}"))?;
    let mesh = stl_io::read_stl(&mut file).map_err(|e| format!("cannot read STL: {e}"))?;
    let vertices: Vec<[f64; 3]> =
        mesh.vertices.iter().map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]).collect();
    let n = vertices.len();
    let mut faces = Vec::with_capacity(mesh.faces.len());
    for (i, f) in mesh.faces.iter().enumerate() {
        if f.vertices.iter().any(|&v| v >= n) {
            return Err(format!("triangle {i} indexes a vertex beyond the {n} vertices"));
        }
        faces.push([f.vertices[0] as u32, f.vertices[1] as u32, f.vertices[2] as u32]);
    }
    Ok((vertices, faces))
}
