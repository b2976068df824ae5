//! Target models: a triangle [`Mesh`], the project's procedural spacecraft (one per symmetry
//! class of the paper) and the user's OBJ/STL files, all in the target's body frame (centred on
//! the bounding-box midpoint, metres).

pub mod decimate;
mod load;
pub mod mesh;
mod procedural;

pub use load::load_mesh_file;
pub use mesh::Mesh;
pub use procedural::{builtin, BUILTIN_NAMES};

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

/// A target: its mesh at real scale and what is known about its symmetry.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetModel {
    pub name: String,
    pub symmetry: SymmetryClass,
    /// Body-frame mesh in real metres, centred on its bounding-box midpoint.
    pub mesh: Mesh,
}

impl TargetModel {
    /// A built-in model by name (see [`BUILTIN_NAMES`]) or a path to an `.obj`/`.stl` file, which
    /// is centred and scaled so its greatest dimension is `GREATEST_DIMENSION_M`.
    pub fn from_spec(spec: &str) -> Result<TargetModel, PerceptionError> {
        if let Some(m) = builtin(spec) {
            return Ok(m);
        }
        let path = Path::new(spec);
        if path.extension().is_none() {
            return Err(PerceptionError::BadModel {
                path: path.to_path_buf(),
                reason: format!(
                    "not a built-in target ({}) and not an .obj/.stl file",
                    BUILTIN_NAMES.join(", ")
                ),
            });
        }
        let mesh =
            load_mesh_file(path)?.centered().scaled_to_greatest_dimension(GREATEST_DIMENSION_M)?;
        Ok(TargetModel {
            name: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| spec.to_string()),
            symmetry: SymmetryClass::Unknown,
            mesh,
        })
    }

    /// The mesh as the camera sees it in the lab: real metres times `scale` (lab m per real m).
    pub fn lab_mesh(&self, scale: f64) -> Result<Mesh, PerceptionError> {
        self.mesh.scaled(scale)
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
