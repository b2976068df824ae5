//! `hitl targets [SPEC...] [--json]`: the built-in targets (or the named ones: a built-in name or
//! an OBJ/STL file) with their faces, size, symmetry and parts, as the estimators and the
//! simulated camera get them (docs/perception.md, "Target models").

use crate::exit;
use hitl_perception::models::{Texture, BUILTIN_NAMES, SPACECRAFT_NAMES};
use hitl_perception::TargetModel;
use serde_json::{json, Value};

/// List the targets: faces, size, symmetry and parts.
#[derive(Debug, clap::Args)]
pub struct TargetsArgs {
    /// Targets to describe: built-in names or .obj/.stl files (default: every built-in, the five
    /// detailed spacecraft first, then the three simple ones).
    pub targets: Vec<String>,
    /// Print one JSON object: `{"targets": [...]}`.
    #[arg(long)]
    pub json: bool,
}

/// What `--json` prints for one target.
pub fn describe(spec: &str, m: &TargetModel) -> Value {
    let (lo, hi) = m.mesh.bounds();
    let size: Vec<f64> = (0..3).map(|k| hi[k] - lo[k]).collect();
    let parts: Vec<Value> = m
        .parts
        .iter()
        .map(|p| {
            let texture = match &p.material.texture {
                None => Value::Null,
                Some(Texture::Png(path)) => json!(path.display().to_string()),
                Some(Texture::CellGrid { .. }) => json!("cell-grid"),
            };
            json!({
                "name": p.name,
                "faces": p.faces.len(),
                "material": {
                    "name": p.material.name,
                    "rgba": p.material.rgba,
                    "specular": p.material.specular,
                    "shininess": p.material.shininess,
                    "texture": texture,
                },
            })
        })
        .collect();
    json!({
        "name": m.name,
        "spec": spec,
        "builtin": BUILTIN_NAMES.contains(&spec) || SPACECRAFT_NAMES.contains(&spec),
        "faces": m.mesh.faces().len(),
        "vertices": m.mesh.vertices().len(),
        "size_m": size,
        "greatest_dimension_m": m.greatest_dimension_m(),
        "symmetry_class": m.symmetry,
        "symmetry": m.symmetry_group.spec,
        "symmetry_rotations": m.symmetry_group.order(),
        "parts": parts,
    })
}

pub fn run(args: TargetsArgs) -> u8 {
    let specs: Vec<String> = if args.targets.is_empty() {
        SPACECRAFT_NAMES.iter().chain(&BUILTIN_NAMES).map(|s| s.to_string()).collect()
    } else {
        args.targets.clone()
    };
    let mut out = Vec::new();
    for spec in &specs {
        match TargetModel::from_spec(spec) {
            Ok(m) => out.push(describe(spec, &m)),
            Err(e) => {
                crate::errln!("hitl targets: {spec}: {e}");
                return exit::BAD_INPUT;
            }
        }
    }
    if args.json {
        crate::outln!("{}", json!({ "targets": out }));
        return exit::OK;
    }
    for t in &out {
        let size = t["size_m"].as_array().map_or(String::new(), |s| {
            s.iter()
                .map(|x| format!("{:.2}", x.as_f64().unwrap_or(0.0)))
                .collect::<Vec<_>>()
                .join(" x ")
        });
        let rotations = match t["symmetry_rotations"].as_u64() {
            Some(1) => "identity only".to_string(),
            Some(n) => format!("{n} rotations"),
            None => "infinitely many rotations".to_string(),
        };
        crate::outln!(
            "{}: {} faces, {size} m, symmetry {} ({}; {rotations})",
            t["name"].as_str().unwrap_or("?"),
            t["faces"],
            t["symmetry"].as_str().unwrap_or("?"),
            t["symmetry_class"].as_str().unwrap_or("?"),
        );
        for p in t["parts"].as_array().into_iter().flatten() {
            crate::outln!(
                "    {:<16} {:>6} faces  {}",
                p["name"].as_str().unwrap_or("?"),
                p["faces"],
                p["material"]["name"].as_str().unwrap_or("?")
            );
        }
    }
    exit::OK
}
