//! How a target looks to a renderer: its parts, each a triangle mesh with one material (colour,
//! specular, shininess, optionally a texture). The estimators never see this: they use the
//! target's one merged [`Mesh`](super::Mesh); the simulated camera draws the parts
//! (docs/sim-camera.md).

use std::path::PathBuf;

/// A texture on a part's material.
#[derive(Debug, Clone, PartialEq)]
pub enum Texture {
    /// A PNG file (an MTL's `map_Kd`), absolute path, checked to exist and to be a PNG.
    Png(PathBuf),
    /// A grid of cells: flat `cell_rgb` tiles edged by `line_rgb` lines, one tile per unit of
    /// texture coordinate (the solar arrays' cells).
    CellGrid { cell_rgb: [f32; 3], line_rgb: [f32; 3] },
}

/// A part's material, in the renderer's terms (MuJoCo's `material`: every value 0..1).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse colour and opacity; multiplies the texture where there is one.
    pub rgba: [f32; 4],
    /// Strength of the specular highlight.
    pub specular: f32,
    /// Sharpness of the specular highlight (MuJoCo: exponent / 128).
    pub shininess: f32,
    pub texture: Option<Texture>,
}

impl Material {
    /// A plain matte grey: what an STL file, an OBJ without an MTL, or a face with no `usemtl`
    /// gets.
    pub fn plain_grey() -> Self {
        Material {
            name: "default".into(),
            rgba: [0.7, 0.7, 0.7, 1.0],
            specular: 0.3,
            shininess: 0.3,
            texture: None,
        }
    }
}

/// One part of a target: the triangles of one material, in the same frame and units as the
/// target's merged mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    pub name: String,
    pub vertices: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// One per vertex, or empty. OBJ convention: (0, 0) is the image's bottom-left corner.
    pub texcoords: Vec<[f32; 2]>,
    pub material: Material,
}

impl Part {
    /// The part moved by `-centre` then scaled by `factor`, the transform that centres and
    /// scales the merged mesh.
    pub(crate) fn transformed(mut self, centre: [f64; 3], factor: f64) -> Part {
        for v in &mut self.vertices {
            for k in 0..3 {
                v[k] = (v[k] - centre[k]) * factor;
            }
        }
        self
    }
}
