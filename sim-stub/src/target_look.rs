//! The target spacecraft in the MJCF scene and how it looks: one triangle mesh in one colour, or
//! parts each with its own material (colour, specular highlight, shininess, a PNG or a built-in
//! cell-grid texture), or, with neither, a primitive composite. Every geom of the target is in
//! the `target` default class and in body [`TARGET_BODY`], which is what the camera's mask
//! counts as target (docs/sim-camera.md).

use crate::mjcf::TARGET_BODY;
use crate::mujoco_plant::StubSceneError;
use hitl_hal::Pose;
use hitl_trajectories::lab::LabConfig;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Vertices and triangles (indices into the vertices) of a mesh.
pub type TriangleMesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// The target spacecraft: a triangle mesh if one is given, else a primitive composite (a bus box
/// with two solar panels and an antenna dish). Either way it is scaled so that its greatest
/// dimension (of its axis-aligned bounding box in the target frame) is `greatest_dimension_m`,
/// and centred on the target frame. Where `parts` are given, the renderer draws them instead of
/// `mesh`, with the same centring and scale (taken from `mesh`'s bounds when there is one, else
/// from the parts').
#[derive(Debug, Clone, PartialEq)]
pub struct TargetModel {
    /// Vertices (target frame, any unit) and triangles (indices into the vertices).
    pub mesh: Option<TriangleMesh>,
    /// Greatest dimension of the model in the lab, metres.
    pub greatest_dimension_m: f64,
    /// The same surface split by material, same frame and unit as `mesh`; empty draws `mesh`
    /// in one plain colour.
    pub parts: Vec<TargetPart>,
}

/// One part of the target: the triangles of one material.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetPart {
    /// A label (the part's or material's name); written into the geom's name.
    pub name: String,
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// One per vertex, or empty; (0, 0) is the texture image's bottom-left corner (OBJ's
    /// convention).
    pub texcoords: Vec<[f32; 2]>,
    pub material: TargetMaterial,
}

/// A part's material in MuJoCo's terms (every value 0..1).
#[derive(Debug, Clone, PartialEq)]
pub struct TargetMaterial {
    /// Colour and opacity; multiplies the texture.
    pub rgba: [f32; 4],
    pub specular: f32,
    pub shininess: f32,
    pub texture: Option<TargetTexture>,
}

/// A part's texture.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetTexture {
    /// A PNG file, absolute path.
    Png(PathBuf),
    /// Flat `cell_rgb` tiles edged by `line_rgb`, one tile per unit of texture coordinate.
    CellGrid { cell_rgb: [f32; 3], line_rgb: [f32; 3] },
}

impl TargetModel {
    /// The primitive spacecraft sized for `lab`: the printed model's size when configured, else
    /// the diameter of the target's keep-out sphere (so it stays inside what preflight checks).
    pub fn for_lab(lab: &LabConfig) -> Self {
        let size = lab.target.model_size_m.unwrap_or(2.0 * lab.target.keepout_radius_m);
        Self { mesh: None, greatest_dimension_m: size, parts: Vec::new() }
    }

    /// Why the model cannot be written into a scene, or `Ok`.
    pub(crate) fn validate(&self) -> Result<(), StubSceneError> {
        let bad = |m: String| Err(StubSceneError::Target(m));
        if !(self.greatest_dimension_m > 0.0 && self.greatest_dimension_m.is_finite()) {
            return bad(format!(
                "greatest_dimension_m = {} must be positive",
                self.greatest_dimension_m
            ));
        }
        if let Some((v, f)) = &self.mesh {
            if v.len() < 4 || f.len() < 4 {
                return bad(format!(
                    "mesh has {} vertices and {} triangles; a solid needs at least 4 of each",
                    v.len(),
                    f.len()
                ));
            }
            check_triangles("mesh", v, f)?;
        }
        for p in &self.parts {
            let what = format!("part {:?}", p.name);
            if p.vertices.len() < 3 || p.faces.is_empty() {
                return bad(format!("{what} has no triangle"));
            }
            check_triangles(&what, &p.vertices, &p.faces)?;
            if !p.texcoords.is_empty() && p.texcoords.len() != p.vertices.len() {
                return bad(format!(
                    "{what} has {} texture coordinates for {} vertices",
                    p.texcoords.len(),
                    p.vertices.len()
                ));
            }
            if p.texcoords.iter().flatten().any(|x| !x.is_finite()) {
                return bad(format!("{what} has a texture coordinate that is not finite"));
            }
            let m = &p.material;
            let unit = |x: f32| (0.0..=1.0).contains(&x);
            if !(m.rgba.iter().all(|x| unit(*x)) && unit(m.specular) && unit(m.shininess)) {
                return bad(format!("{what}: material values must be within 0..1: {m:?}"));
            }
            if let Some(t) = &m.texture {
                if p.texcoords.is_empty() {
                    return bad(format!("{what} has a texture but no texture coordinates"));
                }
                if let TargetTexture::Png(path) = t {
                    if !path.is_absolute() || !path.is_file() {
                        return bad(format!(
                            "{what}: texture {} is not an existing file's absolute path",
                            path.display()
                        ));
                    }
                    if path.to_str().is_none() {
                        return bad(format!(
                            "{what}: texture path {} is not UTF-8",
                            path.display()
                        ));
                    }
                }
            }
        }
        if self.mesh.is_none() && !self.parts.is_empty() {
            let (lo, hi) = self.bounds();
            if (0..3).all(|a| hi[a] - lo[a] <= 0.0) {
                return bad("parts have zero extent".into());
            }
        }
        Ok(())
    }

    /// Bounds of what sets the scale: the mesh, else the parts.
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match &self.mesh {
            Some((v, _)) => bounds(v.iter()),
            None => bounds(self.parts.iter().flat_map(|p| p.vertices.iter())),
        }
    }

    /// Centre and scale that map model units to the target frame in lab metres.
    fn placement(&self) -> ([f64; 3], f64) {
        let (lo, hi) = self.bounds();
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, (lo[2] + hi[2]) / 2.0];
        (centre, self.greatest_dimension_m / extent)
    }
}

fn check_triangles(what: &str, v: &[[f32; 3]], f: &[[u32; 3]]) -> Result<(), StubSceneError> {
    let bad = |m: String| Err(StubSceneError::Target(m));
    if v.iter().flatten().any(|x| !x.is_finite()) {
        return bad(format!("{what} has a vertex that is not a finite number"));
    }
    if let Some(t) = f.iter().find(|t| t.iter().any(|i| *i as usize >= v.len())) {
        return bad(format!("{what} triangle {t:?} indexes past its {} vertices", v.len()));
    }
    let (lo, hi) = bounds(v.iter());
    if (0..3).all(|a| hi[a] - lo[a] <= 0.0) {
        return bad(format!("{what} has zero extent"));
    }
    Ok(())
}

fn bounds<'a>(v: impl Iterator<Item = &'a [f32; 3]>) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in v {
        for a in 0..3 {
            lo[a] = lo[a].min(f64::from(p[a]));
            hi[a] = hi[a].max(f64::from(p[a]));
        }
    }
    (lo, hi)
}

/// Space-separated numbers, each the shortest representation that reads back exactly.
fn nums<T: std::fmt::LowerExp>(v: impl IntoIterator<Item = T>) -> String {
    let mut s = String::new();
    for (i, x) in v.into_iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{x:e}");
    }
    s
}

/// `name` with every character outside `[A-Za-z0-9_-]` replaced by `_` (MJCF names).
fn label(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}

/// `text` escaped for an XML attribute value.
fn xml_attr(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&apos;"),
            c => s.push(c),
        }
    }
    s
}

/// The target's `<asset>` block (meshes, textures, materials); nothing for the primitive
/// composite. Call after [`TargetModel::validate`].
pub(crate) fn write_assets(x: &mut String, target: &TargetModel) {
    if target.mesh.is_none() && target.parts.is_empty() {
        return;
    }
    let (centre, scale) = target.placement();
    let place = |v: &[[f32; 3]]| -> String {
        nums(v.iter().flat_map(|p| (0..3).map(move |a| (f64::from(p[a]) - centre[a]) * scale)))
    };
    let _ = writeln!(x, "  <asset>");
    if target.parts.is_empty() {
        if let Some((v, f)) = &target.mesh {
            let _ = writeln!(
                x,
                "    <mesh name=\"target_mesh\" inertia=\"shell\" vertex=\"{}\" face=\"{}\"/>",
                place(v),
                f.iter().flatten().map(|i| i.to_string()).collect::<Vec<_>>().join(" ")
            );
        }
    }
    for (i, p) in target.parts.iter().enumerate() {
        let faces = p.faces.iter().flatten().map(|i| i.to_string()).collect::<Vec<_>>().join(" ");
        let texcoord = if p.texcoords.is_empty() {
            String::new()
        } else {
            // MuJoCo's texture rows run top to bottom: v is flipped, as its own OBJ reader does.
            format!(" texcoord=\"{}\"", nums(p.texcoords.iter().flat_map(|t| [t[0], 1.0 - t[1]])))
        };
        let _ = writeln!(
            x,
            "    <mesh name=\"target_part{i}\" inertia=\"shell\" vertex=\"{}\" face=\"{faces}\"{texcoord}/>",
            place(&p.vertices)
        );
        let m = &p.material;
        let texture = match &m.texture {
            None => String::new(),
            Some(TargetTexture::Png(path)) => {
                let _ = writeln!(
                    x,
                    "    <texture name=\"target_tex{i}\" type=\"2d\" file=\"{}\"/>",
                    xml_attr(&path.to_string_lossy())
                );
                format!(" texture=\"target_tex{i}\"")
            }
            Some(TargetTexture::CellGrid { cell_rgb, line_rgb }) => {
                let _ = writeln!(
                    x,
                    "    <texture name=\"target_tex{i}\" type=\"2d\" builtin=\"flat\" rgb1=\"{}\" mark=\"edge\" markrgb=\"{}\" width=\"64\" height=\"64\"/>",
                    nums(*cell_rgb),
                    nums(*line_rgb)
                );
                format!(" texture=\"target_tex{i}\"")
            }
        };
        let _ = writeln!(
            x,
            "    <material name=\"target_mat{i}\" rgba=\"{}\" specular=\"{}\" shininess=\"{}\"{texture}/>",
            nums(m.rgba),
            nums([m.specular]),
            nums([m.shininess])
        );
    }
    let _ = writeln!(x, "  </asset>");
}

/// The target's body at `pose` (MJCF `pos`/`quat` attributes of the lab frame), its geoms in
/// the `target` class.
pub(crate) fn write_target(x: &mut String, pose: &Pose, target: &TargetModel) {
    let t = pose.translation.vector;
    let q = pose.rotation;
    let _ = writeln!(
        x,
        "    <body name=\"{TARGET_BODY}\" pos=\"{}\" quat=\"{}\">",
        nums([t.x, t.y, t.z]),
        nums([q.w, q.i, q.j, q.k])
    );
    if !target.parts.is_empty() {
        for (i, p) in target.parts.iter().enumerate() {
            let _ = writeln!(
                x,
                "      <geom name=\"target-{i}-{}\" class=\"target\" type=\"mesh\" mesh=\"target_part{i}\" material=\"target_mat{i}\"/>",
                label(&p.name)
            );
        }
    } else if target.mesh.is_some() {
        let _ = writeln!(
            x,
            "      <geom name=\"target-mesh\" class=\"target\" type=\"mesh\" mesh=\"target_mesh\" rgba=\"0.8 0.8 0.8 1\"/>"
        );
    } else {
        // Bus: a cube of 0.3 D; panels from the bus's +-y faces out to +-D/2; a dish on +z.
        let d = target.greatest_dimension_m;
        let bus = 0.15 * d;
        let panel_len = (0.5 * d - bus) / 2.0;
        let panel_y = bus + panel_len;
        type Part = (&'static str, &'static str, [f64; 3], [f64; 3], &'static str);
        let parts: [Part; 4] = [
            ("target-bus", "box", [0.0, 0.0, 0.0], [bus, bus, bus], "0.85 0.65 0.25 1"),
            (
                "target-panel-y+",
                "box",
                [0.0, panel_y, 0.0],
                [0.12 * d, panel_len, 0.005 * d],
                "0.10 0.15 0.45 1",
            ),
            (
                "target-panel-y-",
                "box",
                [0.0, -panel_y, 0.0],
                [0.12 * d, panel_len, 0.005 * d],
                "0.10 0.15 0.45 1",
            ),
            (
                "target-dish",
                "cylinder",
                [0.0, 0.0, bus + 0.01 * d],
                [0.08 * d, 0.01 * d, 0.0],
                "0.9 0.9 0.9 1",
            ),
        ];
        for (name, kind, p, s, rgba) in parts {
            let size = if kind == "cylinder" { nums(s[..2].iter().copied()) } else { nums(s) };
            let _ = writeln!(
                x,
                "      <geom name=\"{name}\" class=\"target\" type=\"{kind}\" pos=\"{}\" size=\"{size}\" rgba=\"{rgba}\"/>",
                nums(p)
            );
        }
    }
    let _ = writeln!(x, "    </body>");
}
