//! Target models: a triangle [`Mesh`], the project's procedural spacecraft (one per symmetry
//! class of the paper) and the user's OBJ/STL files, all in the target's body frame (centred on
//! the bounding-box midpoint, metres). Each also has parts with materials ([`look`]) for the
//! simulated camera.

pub mod decimate;
mod detailed;
mod load;
pub mod look;
pub mod mesh;
mod procedural;
pub mod symmetry;

pub use detailed::SPACECRAFT_NAMES;
pub use load::{load_mesh_file, load_model_file};
pub use look::{Material, Part, Texture};
pub use mesh::Mesh;
pub use procedural::{builtin, BUILTIN_NAMES};
pub use symmetry::Symmetry;

use crate::PerceptionError;
use std::path::Path;

/// The paper's symmetry classes of spacecraft geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SymmetryClass {
    /// No mirror plane.
    None,
    /// One mirror plane.
    OnePlane,
    /// Two mirror planes.
    TwoPlanes,
    /// Not known (a user's file).
    Unknown,
}

/// The real-scale greatest dimension every target is normalised to (paper, RQ3): 2 m.
pub const GREATEST_DIMENSION_M: f64 = 2.0;

/// A target: its mesh at real scale, what is known about its symmetry, and how it looks.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetModel {
    pub name: String,
    pub symmetry: SymmetryClass,
    /// The proper rotations that map the target onto itself (what the symmetry-aware score
    /// forgives): a built-in's own; a file's from its `FILE.symmetry` declaration, else none.
    pub symmetry_group: Symmetry,
    /// Body-frame mesh in real metres, centred on its bounding-box midpoint: what the
    /// estimators register against.
    pub mesh: Mesh,
    /// The same surface as parts with materials, same frame and units: what the simulated
    /// camera draws. Every triangle of `mesh` is in one part (an OBJ's are the same triangles;
    /// a built-in's boxes have their corners repeated per face for flat shading).
    pub parts: Vec<Part>,
}

impl TargetModel {
    /// A built-in model by name (see [`BUILTIN_NAMES`]) or a path to an `.obj`/`.stl` file, which
    /// is centred and scaled so its greatest dimension is `GREATEST_DIMENSION_M`; a file's
    /// symmetry comes from the declaration next to it (`FILE.symmetry`, [`Symmetry::read_sidecar`]).
    pub fn from_spec(spec: &str) -> Result<TargetModel, PerceptionError> {
        if let Some(m) = builtin(spec) {
            return Ok(m);
        }
        let path = Path::new(spec);
        if path.extension().is_none() {
            return Err(PerceptionError::BadModel {
                path: path.to_path_buf(),
                reason: format!(
                    "not a built-in target ({}, {}) and not an .obj/.stl file",
                    SPACECRAFT_NAMES.join(", "),
                    BUILTIN_NAMES.join(", ")
                ),
            });
        }
        let (raw, parts) = load_model_file(path)?;
        let (lo, hi) = raw.bounds();
        let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
        let factor = GREATEST_DIMENSION_M / raw.greatest_dimension();
        let mesh = raw.centered().scaled(factor)?;
        let parts = parts.into_iter().map(|p| p.transformed(centre, factor)).collect();
        let symmetry_group =
            Symmetry::read_sidecar(path, centre, factor)?.unwrap_or_else(Symmetry::none);
        Ok(TargetModel {
            name: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| spec.to_string()),
            symmetry: SymmetryClass::Unknown,
            symmetry_group,
            mesh,
            parts,
        })
    }

    /// The mesh as the camera sees it in the lab: real metres times `scale` (lab m per real m).
    pub fn lab_mesh(&self, scale: f64) -> Result<Mesh, PerceptionError> {
        self.mesh.scaled(scale)
    }

    /// The declared symmetry as the camera sees it in the lab: its point scaled as
    /// [`Self::lab_mesh`] scales the mesh.
    pub fn lab_symmetry(&self, scale: f64) -> Symmetry {
        self.symmetry_group.clone().transformed([0.0; 3], scale)
    }

    /// Greatest dimension in real metres.
    pub fn greatest_dimension_m(&self) -> f64 {
        self.mesh.greatest_dimension()
    }

    /// Vertices and faces for a renderer (the stub's `TargetModel.mesh`), real metres.
    pub fn vertices_faces(&self) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        self.mesh.to_f32()
    }
}
