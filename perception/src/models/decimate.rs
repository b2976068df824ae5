//! Mesh resolution for the estimator: quadric decimation of a target [`Mesh`] to a face budget,
//! through meshoptimizer's simplifier (the `meshopt` crate), as the paper's RQ2 decimates the
//! estimator's model. Only the estimator's copy is ever decimated (`hitl eval --mesh-faces`);
//! the rendered target keeps its own mesh.
//!
//! Steps: weld vertices that share a position (flat-shaded models duplicate them per face, which
//! would pin every seam), collapse edges by quadric error until the face budget is met, and when
//! the topology stops the quadric pass above the budget (separate parts, open borders) finish with
//! meshoptimizer's sloppy simplifier, which always reaches it. Unused vertices are dropped.

use super::Mesh;
use crate::PerceptionError;

/// The fewest faces a decimated mesh may be asked for.
pub const MIN_FACES: usize = 4;

/// What a decimation did.
#[derive(Debug, Clone, PartialEq)]
pub struct Decimated {
    pub mesh: Mesh,
    /// Faces before (after welding is the same count: welding drops vertices, not faces).
    pub faces_before: usize,
    /// The quadric pass alone reached the budget (false: the sloppy pass finished it).
    pub quadric_only: bool,
}

/// Decimate `mesh` to at most `target_faces` faces (a mesh already at or below it is returned
/// unchanged). Errors on a budget below [`MIN_FACES`] or when nothing usable is left.
pub fn decimate(mesh: &Mesh, target_faces: usize) -> Result<Decimated, PerceptionError> {
    if target_faces < MIN_FACES {
        return Err(PerceptionError::BadInput(format!(
            "mesh faces {target_faces}: at least {MIN_FACES} are needed"
        )));
    }
    let faces_before = mesh.faces().len();
    if faces_before <= target_faces {
        return Ok(Decimated { mesh: mesh.clone(), faces_before, quadric_only: true });
    }
    let positions: Vec<[f32; 3]> =
        mesh.vertices().iter().map(|v| [v[0] as f32, v[1] as f32, v[2] as f32]).collect();
    let indices: Vec<u32> = mesh.faces().iter().flatten().copied().collect();
    // Weld: one vertex per distinct position.
    let (count, remap) = meshopt::generate_vertex_remap(&positions, Some(&indices));
    let welded_idx = meshopt::remap_index_buffer(Some(&indices), count, &remap);
    let welded_pos = meshopt::remap_vertex_buffer(&positions, count, &remap);

    let target_index_count = target_faces * 3;
    // target_error 1.0 (relative to the mesh extent): the face budget, not an error bound, stops it.
    let mut out = meshopt::simplify_decoder(
        &welded_idx,
        &welded_pos,
        target_index_count,
        1.0,
        meshopt::SimplifyOptions::None,
        None,
    );
    let quadric_only = out.len() <= target_index_count;
    if !quadric_only {
        out = meshopt::simplify_sloppy_decoder(&out, &welded_pos, target_index_count, 1.0, None);
    }
    // The original vertex behind each welded one (the simplifiers only drop vertices, so the
    // original double-precision position is exact).
    let mut original = vec![0usize; count];
    for (i, &w) in remap.iter().enumerate().rev() {
        if let Some(o) = original.get_mut(w as usize) {
            *o = i;
        }
    }
    // Keep used vertices only, in first-use order (deterministic).
    let mut new_index = vec![u32::MAX; welded_pos.len()];
    let mut vertices = Vec::new();
    let mut faces = Vec::with_capacity(out.len() / 3);
    for tri in out.chunks_exact(3) {
        let mut f = [0u32; 3];
        for (k, &v) in tri.iter().enumerate() {
            let slot = &mut new_index[v as usize];
            if *slot == u32::MAX {
                *slot = vertices.len() as u32;
                vertices.push(mesh.vertices()[original[v as usize]]);
            }
            f[k] = *slot;
        }
        if f[0] != f[1] && f[1] != f[2] && f[0] != f[2] {
            faces.push(f);
        }
    }
    let mesh = Mesh::new(vertices, faces)
        .map_err(|e| PerceptionError::BadMesh(format!("decimated to {target_faces} faces: {e}")))?;
    Ok(Decimated { mesh, faces_before, quadric_only })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A w x h grid of unit squares in the plane z = 0 (2 w h faces), plus a bump in the middle so
    /// the quadric error is not zero everywhere.
    fn grid(w: u32, h: u32) -> Mesh {
        let mut v = Vec::new();
        for j in 0..=h {
            for i in 0..=w {
                let bump = if i == w / 2 && j == h / 2 { 0.5 } else { 0.0 };
                v.push([i as f64, j as f64, bump]);
            }
        }
        let mut f = Vec::new();
        for j in 0..h {
            for i in 0..w {
                let a = j * (w + 1) + i;
                f.push([a, a + 1, a + w + 2]);
                f.push([a, a + w + 2, a + w + 1]);
            }
        }
        Mesh::new(v, f).expect("grid")
    }

    #[test]
    fn reaches_the_budget_and_keeps_the_extent() {
        let m = grid(40, 40);
        assert_eq!(m.faces().len(), 3200);
        for budget in [1000, 100, 10] {
            let d = decimate(&m, budget).expect("decimate");
            let n = d.mesh.faces().len();
            assert!(n <= budget && n >= budget / 4, "{budget}: got {n} faces");
            assert!((d.mesh.greatest_dimension() - 40.0).abs() < 1e-9, "corners kept");
            assert_eq!(d.faces_before, 3200);
        }
    }

    #[test]
    fn small_meshes_pass_through_and_tiny_budgets_are_refused() {
        let m = grid(2, 2);
        let d = decimate(&m, 100).expect("decimate");
        assert_eq!(d.mesh, m);
        assert!(decimate(&m, 2).is_err());
    }

    #[test]
    fn builtin_targets_decimate() {
        for name in crate::models::BUILTIN_NAMES {
            let t = crate::TargetModel::from_spec(name).expect("builtin");
            let n0 = t.mesh.faces().len();
            let budget = (n0 / 2).max(MIN_FACES);
            let d = decimate(&t.mesh, budget).expect("decimate");
            assert!(d.mesh.faces().len() <= budget, "{name}: {n0} -> {}", d.mesh.faces().len());
            assert!(d.mesh.greatest_dimension() > 1.0, "{name}: extent kept");
        }
    }
}
