//! Loading the user's target meshes: Wavefront OBJ (`tobj`) with its MTL materials and PNG
//! textures, and STL, ASCII or binary (`stl_io`, one plain material). A file that cannot be
//! drawn as written (a missing MTL or texture, a `usemtl` of no known material, a texture
//! without texture coordinates, a face index past the vertices) is an error naming the file.

use super::look::{Material, Part, Texture};
use super::Mesh;
use crate::PerceptionError;
use std::cell::RefCell;
use std::path::{Path, PathBuf};

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

/// Loads an `.obj` (with its materials and textures) or `.stl` file as one merged mesh and its
/// parts, one per material, in the file's units. Stricter than [`load_mesh_file`]: a renderer
/// needs the materials the file names.
pub fn load_model_file(path: &Path) -> Result<(Mesh, Vec<Part>), PerceptionError> {
    let bad = |reason: String| PerceptionError::BadModel { path: path.to_path_buf(), reason };
    let ext =
        path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let ((vertices, faces), parts) = match ext.as_str() {
        "obj" => load_obj_parts(path).map_err(bad)?,
        "stl" => {
            let raw = load_stl(path).map_err(bad)?;
            let part = Part {
                name: "stl".into(),
                vertices: raw.0.clone(),
                faces: raw.1.clone(),
                texcoords: Vec::new(),
                material: Material::plain_grey(),
            };
            (raw, vec![part])
        }
        other => {
            return Err(bad(format!("unsupported mesh format {other:?} (expected .obj or .stl)")))
        }
    };
    let mesh = Mesh::new(vertices, faces).map_err(|e| bad(e.to_string()))?;
    Ok((mesh, parts))
}

type Raw = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A material library as loaded: where it is and the names it defines.
struct Library {
    path: PathBuf,
    names: Vec<String>,
}

fn load_obj_parts(path: &Path) -> Result<(Raw, Vec<Part>), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot open: {e}"))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let libraries: RefCell<Vec<Library>> = RefCell::new(Vec::new());
    let failure: RefCell<Option<String>> = RefCell::new(None);
    let loader = |mtl: &Path| {
        let full = dir.join(mtl);
        let result = tobj::load_mtl(&full);
        match &result {
            Ok((mats, _)) => libraries
                .borrow_mut()
                .push(Library { path: full, names: mats.iter().map(|m| m.name.clone()).collect() }),
            Err(e) => {
                let why = match e {
                    tobj::LoadError::OpenFileFailed => "cannot be opened (missing?)".to_string(),
                    other => format!("cannot be read: {other}"),
                };
                failure
                    .borrow_mut()
                    .get_or_insert(format!("material library {} (mtllib) {why}", full.display()));
            }
        }
        result
    };
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) = tobj::load_obj_buf(&mut std::io::Cursor::new(&bytes), &opts, loader)
        .map_err(|e| format!("cannot read OBJ: {e}"))?;
    if let Some(why) = failure.into_inner() {
        return Err(why);
    }
    let materials = materials.map_err(|e| format!("cannot read its materials: {e}"))?;
    let libraries = libraries.into_inner();
    // tobj drops a `usemtl` of a name no library defines; a renderer would draw it grey.
    let text = String::from_utf8_lossy(&bytes);
    for line in text.lines() {
        let Some(name) = line.trim_start().strip_prefix("usemtl") else { continue };
        let name = name.trim();
        if !name.is_empty() && !materials.iter().any(|m| m.name == name) {
            let libs: Vec<String> =
                libraries.iter().map(|l| l.path.display().to_string()).collect();
            return Err(if libs.is_empty() {
                format!("usemtl {name:?} but the file names no material library (mtllib)")
            } else {
                format!("usemtl {name:?} is not defined in {}", libs.join(", "))
            });
        }
    }
    let (vertices, faces) = merge_objects(&models)?;
    let mut parts: Vec<(Option<usize>, Part)> = Vec::new();
    for m in &models {
        let mesh = &m.mesh;
        let n = mesh.positions.len() / 3;
        let has_uv = !mesh.texcoords.is_empty();
        if has_uv && mesh.texcoords.len() != 2 * n {
            return Err(format!(
                "object {:?} has texture coordinates on some faces only ({} for {n} vertices)",
                m.name,
                mesh.texcoords.len() / 2
            ));
        }
        let i = match parts.iter().position(|(id, _)| *id == mesh.material_id) {
            Some(i) => i,
            None => {
                let material = match mesh.material_id.and_then(|id| materials.get(id)) {
                    Some(mat) => convert_material(mat, &libraries)?,
                    None => Material::plain_grey(),
                };
                let part = Part {
                    name: material.name.clone(),
                    vertices: Vec::new(),
                    faces: Vec::new(),
                    texcoords: Vec::new(),
                    material,
                };
                parts.push((mesh.material_id, part));
                parts.len() - 1
            }
        };
        let part = &mut parts[i].1;
        let textured = part.material.texture.is_some();
        if textured && !has_uv {
            return Err(format!(
                "material {:?} has a texture but object {:?} has no texture coordinates (vt)",
                part.name, m.name
            ));
        }
        // Texture coordinates are kept only where every object of the part has them.
        let base = part.vertices.len() as u32;
        let part_has_uv = part.texcoords.len() == part.vertices.len();
        part.vertices.extend(
            mesh.positions.chunks_exact(3).map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
        );
        if has_uv && part_has_uv {
            part.texcoords.extend(mesh.texcoords.chunks_exact(2).map(|t| [t[0], t[1]]));
        } else {
            part.texcoords.clear();
        }
        part.faces
            .extend(mesh.indices.chunks_exact(3).map(|f| [base + f[0], base + f[1], base + f[2]]));
    }
    Ok(((vertices, faces), parts.into_iter().map(|(_, p)| p).collect()))
}

/// A material in the renderer's terms, its texture resolved next to its library and checked.
fn convert_material(mat: &tobj::Material, libraries: &[Library]) -> Result<Material, String> {
    let lib = libraries.iter().find(|l| l.names.contains(&mat.name));
    let texture = match mat.diffuse_texture.as_deref().map(str::trim).filter(|t| !t.is_empty()) {
        None => None,
        Some(spec) => {
            // `map_Kd [-options ...] file`: the file is the last word.
            let file = spec.split_whitespace().last().unwrap_or(spec);
            let base = lib.and_then(|l| l.path.parent()).unwrap_or(Path::new("."));
            Some(Texture::Png(check_png(&base.join(file), &mat.name)?))
        }
    };
    let unit = |x: f32| if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    let diffuse = mat.diffuse.unwrap_or(if texture.is_some() { [1.0; 3] } else { [0.7; 3] });
    let specular = mat.specular.map(|s| (s[0] + s[1] + s[2]) / 3.0).unwrap_or(0.3);
    Ok(Material {
        name: mat.name.clone(),
        rgba: [
            unit(diffuse[0]),
            unit(diffuse[1]),
            unit(diffuse[2]),
            unit(mat.dissolve.unwrap_or(1.0)),
        ],
        specular: unit(specular),
        // MTL's Ns is the Phong exponent; MuJoCo's shininess is that exponent over 128.
        shininess: unit(mat.shininess.unwrap_or(38.4) / 128.0),
        texture,
    })
}

/// The texture file `path` of material `material`, made absolute, if it is a readable PNG (the
/// only image format MuJoCo reads).
fn check_png(path: &Path, material: &str) -> Result<PathBuf, String> {
    let mut head = [0u8; 8];
    let read = std::fs::File::open(path).and_then(|mut f| {
        use std::io::Read;
        f.read_exact(&mut head)
    });
    if let Err(e) = read {
        return Err(format!(
            "texture {} of material {material:?} cannot be read: {e}",
            path.display()
        ));
    }
    if head != *b"\x89PNG\r\n\x1a\n" {
        return Err(format!(
            "texture {} of material {material:?} is not a PNG file (the renderer reads PNG only)",
            path.display()
        ));
    }
    std::fs::canonicalize(path)
        .map_err(|e| format!("texture {} of material {material:?}: {e}", path.display()))
}

/// The geometry of an OBJ, its materials not read.
fn load_obj(path: &Path) -> Result<Raw, String> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _materials) =
        tobj::load_obj(path, &opts).map_err(|e| format!("cannot read OBJ: {e}"))?;
    merge_objects(&models)
}

/// Every object's triangles in one mesh, indices checked.
fn merge_objects(models: &[tobj::Model]) -> Result<Raw, String> {
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    for m in models {
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
