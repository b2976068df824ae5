//! Campaign manifests: a TOML file with a `[run]` table of fixed run parameters and a `[matrix]`
//! table (or several `[[matrix]]` tables) of lists; the cases are the product of each matrix
//! table's lists, tables one after another, numbered in a stable order that does not depend on
//! how the file orders its keys (keys in [`KEYS`] order, the last key varying fastest). Every case
//! carries a stable id: a hash of its full definition (defaults filled in), so its outputs can be
//! recognised on a rerun. Unknown keys, wrong types and values out of range are refused with the
//! key's name (exit 2 at the CLI).

use serde_json::{json, Value};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// What kind of value a key takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// A string.
    Text,
    /// A positive number.
    Positive,
    /// A non-negative integer.
    Count,
    /// `FROM:TO` degrees (a window of oriented Sun phase, or of argument of latitude).
    Window,
    /// An integer face budget, or "full" for the ground-truth mesh as it is.
    Faces,
    /// A path, resolved relative to the manifest's folder (`[run]` only).
    File,
    /// An integer (`[run]` only: priorities).
    Int,
}

/// One key of a manifest: its name, kind, default, and whether `[matrix]` may vary it.
struct KeyDef {
    name: &'static str,
    kind: Kind,
    default: Option<fn() -> Value>,
    matrix: bool,
}

/// The keys a manifest may use, in case order (the case product varies the last one fastest).
const KEYS: &[KeyDef] = &[
    KeyDef { name: "preset", kind: Kind::Text, default: Some(|| json!("flyaround")), matrix: true },
    KeyDef { name: "scene_kind", kind: Kind::Text, default: None, matrix: true },
    KeyDef {
        name: "camera_preset",
        kind: Kind::Text,
        default: Some(|| json!("wfov")),
        matrix: true,
    },
    KeyDef { name: "camera_size", kind: Kind::Text, default: None, matrix: true },
    KeyDef { name: "range_m", kind: Kind::Positive, default: Some(|| json!(10.0)), matrix: true },
    KeyDef { name: "sun_phase_deg", kind: Kind::Window, default: None, matrix: true },
    KeyDef { name: "arc_deg", kind: Kind::Window, default: None, matrix: true },
    KeyDef {
        name: "target",
        kind: Kind::Text,
        default: Some(|| json!("asymmetric")),
        matrix: true,
    },
    KeyDef { name: "perception", kind: Kind::Text, default: Some(|| json!("icp")), matrix: true },
    KeyDef { name: "mesh_faces", kind: Kind::Faces, default: Some(|| json!("full")), matrix: true },
    KeyDef {
        name: "duration_s",
        kind: Kind::Positive,
        default: Some(|| json!(20.0)),
        matrix: true,
    },
    KeyDef {
        name: "capture_every_s",
        kind: Kind::Positive,
        default: Some(|| json!(0.5)),
        matrix: true,
    },
    KeyDef { name: "reregister_every", kind: Kind::Count, default: None, matrix: true },
    KeyDef { name: "config", kind: Kind::File, default: None, matrix: false },
    KeyDef { name: "rt_priority", kind: Kind::Int, default: None, matrix: false },
];

/// Keys of the optional `[campaign]` table (not run parameters: they do not enter case ids).
const CAMPAIGN_KEYS: &[&str] = &["name", "description"];

/// A manifest that cannot be used; the message names the key or the TOML error.
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestError(pub String);

impl fmt::Display for ManifestError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ManifestError {}

fn bad(msg: impl Into<String>) -> ManifestError {
    ManifestError(msg.into())
}

/// One case: its number in the campaign, its id and its full definition (every key with a value,
/// defaults filled in).
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    pub index: usize,
    pub id: String,
    /// Key -> value (JSON: strings, numbers), in key order.
    pub params: BTreeMap<String, Value>,
    /// The keys the matrix varies for this case (for tables and plots).
    pub varied: Vec<String>,
}

impl Case {
    pub fn text(&self, key: &str) -> Option<&str> {
        self.params.get(key).and_then(|v| v.as_str())
    }

    pub fn number(&self, key: &str) -> Option<f64> {
        self.params.get(key).and_then(|v| v.as_f64())
    }

    /// The estimator's face budget: `None` for the ground-truth mesh as it is.
    pub fn mesh_faces(&self) -> Option<u64> {
        self.params.get("mesh_faces").and_then(|v| v.as_u64())
    }

    /// A parameter as a table cell ("" when unset).
    pub fn cell(&self, key: &str) -> String {
        match self.params.get(key) {
            None | Some(Value::Null) => String::new(),
            Some(Value::String(s)) => s.clone(),
            Some(v) => v.as_f64().map_or_else(|| v.to_string(), |x| format!("{x}")),
        }
    }

    /// The definition as one JSON object (what the id hashes).
    pub fn definition(&self) -> Value {
        Value::Object(self.params.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
    }
}

/// A parsed manifest and its cases.
#[derive(Debug, Clone)]
pub struct Manifest {
    pub path: PathBuf,
    pub name: String,
    pub cases: Vec<Case>,
    /// The keys any matrix table varies, in key order.
    pub varied: Vec<String>,
}

/// Every key name a manifest may use, in case order.
pub fn key_names() -> Vec<&'static str> {
    KEYS.iter().map(|k| k.name).collect()
}

fn key_def(name: &str) -> Option<&'static KeyDef> {
    KEYS.iter().find(|k| k.name == name)
}

/// Parse `FROM:TO` degrees.
pub fn parse_window(text: &str) -> Option<(f64, f64)> {
    let (a, b) = text.split_once(':')?;
    let a: f64 = a.trim().parse().ok()?;
    let b: f64 = b.trim().parse().ok()?;
    (a.is_finite() && b.is_finite()).then_some((a, b))
}

/// Check and normalise one value of `key`; `base` resolves relative paths.
fn value(key: &KeyDef, v: &toml::Value, base: &Path) -> Result<Value, ManifestError> {
    let name = key.name;
    let num = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        _ => None,
    };
    match key.kind {
        Kind::Text => match v {
            toml::Value::String(s) if !s.trim().is_empty() => Ok(json!(s)),
            _ => Err(bad(format!("`{name}`: expected a non-empty string, got {v}"))),
        },
        Kind::Positive => match num(v) {
            Some(x) if x.is_finite() && x > 0.0 => Ok(json!(x)),
            _ => Err(bad(format!("`{name}`: expected a positive number, got {v}"))),
        },
        Kind::Count => match v {
            toml::Value::Integer(i) if *i >= 0 => Ok(json!(*i)),
            _ => Err(bad(format!("`{name}`: expected a non-negative integer, got {v}"))),
        },
        Kind::Int => match v {
            toml::Value::Integer(i) => Ok(json!(*i)),
            _ => Err(bad(format!("`{name}`: expected an integer, got {v}"))),
        },
        Kind::Window => match v {
            toml::Value::String(s) => match parse_window(s) {
                Some((a, b)) => Ok(json!(format!("{a}:{b}"))),
                None => Err(bad(format!("`{name}`: expected \"FROM:TO\" in degrees, got {v}"))),
            },
            _ => Err(bad(format!("`{name}`: expected \"FROM:TO\" in degrees, got {v}"))),
        },
        Kind::Faces => match v {
            toml::Value::String(s) if s == "full" => Ok(json!("full")),
            toml::Value::Integer(i) if *i >= 4 => Ok(json!(*i)),
            _ => Err(bad(format!(
                "`{name}`: expected a face count of at least 4, or \"full\" (the ground-truth \
                 mesh as it is), got {v}"
            ))),
        },
        Kind::File => match v {
            toml::Value::String(s) if !s.is_empty() => {
                let p = Path::new(s);
                let p = if p.is_absolute() { p.to_path_buf() } else { base.join(p) };
                Ok(json!(p.to_string_lossy()))
            }
            _ => Err(bad(format!("`{name}`: expected a path, got {v}"))),
        },
    }
}

/// Read and expand a manifest file.
pub fn load(path: &Path) -> Result<Manifest, ManifestError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| bad(format!("{}: {e}", path.display())))?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let base = if base.as_os_str().is_empty() { PathBuf::from(".") } else { base };
    let base = std::fs::canonicalize(&base).unwrap_or(base);
    let default_name =
        path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    parse(&text, &base, &default_name)
        .map(|mut m| {
            m.path = path.to_path_buf();
            m
        })
        .map_err(|e| bad(format!("{}: {e}", path.display())))
}

/// Expand manifest text; relative paths resolve against `base`.
pub fn parse(text: &str, base: &Path, default_name: &str) -> Result<Manifest, ManifestError> {
    let doc: toml::Table = text.parse().map_err(|e: toml::de::Error| bad(e.to_string()))?;
    let mut name = default_name.to_string();
    let mut fixed: BTreeMap<&'static str, Value> = BTreeMap::new();
    let mut matrices: Vec<Vec<(&'static KeyDef, Vec<Value>)>> = Vec::new();
    for (section, v) in &doc {
        match section.as_str() {
            "campaign" => {
                let t = v.as_table().ok_or_else(|| bad("[campaign] must be a table"))?;
                for (k, v) in t {
                    if !CAMPAIGN_KEYS.contains(&k.as_str()) {
                        return Err(bad(format!(
                            "unknown key `{k}` in [campaign] (known: {})",
                            CAMPAIGN_KEYS.join(", ")
                        )));
                    }
                    if k == "name" {
                        name = v
                            .as_str()
                            .filter(|s| !s.is_empty())
                            .ok_or_else(|| bad("[campaign] `name` must be a non-empty string"))?
                            .to_string();
                    }
                }
            }
            "run" => {
                let t = v.as_table().ok_or_else(|| bad("[run] must be a table"))?;
                for (k, v) in t {
                    let def = key_def(k).ok_or_else(|| unknown(k, "[run]"))?;
                    fixed.insert(def.name, value(def, v, base)?);
                }
            }
            "matrix" => {
                let tables: Vec<&toml::Table> = match v {
                    toml::Value::Table(t) => vec![t],
                    toml::Value::Array(a) => a
                        .iter()
                        .map(|t| t.as_table().ok_or_else(|| bad("[[matrix]] must hold tables")))
                        .collect::<Result<_, _>>()?,
                    _ => return Err(bad("`matrix` must be a table ([matrix] or [[matrix]])")),
                };
                for t in tables {
                    let mut axes = Vec::new();
                    for (k, v) in t {
                        let def = key_def(k).ok_or_else(|| unknown(k, "[matrix]"))?;
                        if !def.matrix {
                            return Err(bad(format!(
                                "`{k}` is fixed for a campaign: put it in [run], not [matrix]"
                            )));
                        }
                        let list = v.as_array().ok_or_else(|| {
                            bad(format!("[matrix] `{k}`: expected a list of values, got {v}"))
                        })?;
                        if list.is_empty() {
                            return Err(bad(format!("[matrix] `{k}`: the list is empty")));
                        }
                        let vals =
                            list.iter().map(|x| value(def, x, base)).collect::<Result<_, _>>()?;
                        axes.push((def, vals));
                    }
                    axes.sort_by_key(|(d, _)| KEYS.iter().position(|k| k.name == d.name));
                    matrices.push(axes);
                }
            }
            other => {
                return Err(bad(format!(
                    "unknown table `{other}` (a manifest has [campaign], [run] and [matrix])"
                )))
            }
        }
    }
    for axes in &matrices {
        if let Some((d, _)) = axes.iter().find(|(d, _)| fixed.contains_key(d.name)) {
            return Err(bad(format!(
                "`{}` is in both [run] and [matrix]: give it in one place",
                d.name
            )));
        }
    }
    if matrices.is_empty() {
        matrices.push(Vec::new());
    }
    let mut varied: Vec<String> = Vec::new();
    for def in KEYS {
        if matrices.iter().any(|axes| axes.iter().any(|(d, _)| d.name == def.name)) {
            varied.push(def.name.to_string());
        }
    }
    let mut cases = Vec::new();
    for axes in &matrices {
        let total: usize = axes.iter().map(|(_, v)| v.len()).product();
        for n in 0..total {
            // Mixed radix, the last axis fastest.
            let mut rest = n;
            let mut pick = vec![0usize; axes.len()];
            for (slot, (_, vals)) in pick.iter_mut().zip(axes.iter()).rev() {
                *slot = rest % vals.len();
                rest /= vals.len();
            }
            let mut params = BTreeMap::new();
            for def in KEYS {
                let v = axes
                    .iter()
                    .zip(&pick)
                    .find(|((d, _), _)| d.name == def.name)
                    .map(|((_, vals), &i)| vals[i].clone())
                    .or_else(|| fixed.get(def.name).cloned())
                    .or_else(|| def.default.map(|f| f()));
                if let Some(v) = v {
                    params.insert(def.name.to_string(), v);
                }
            }
            let case_varied = axes.iter().map(|(d, _)| d.name.to_string()).collect();
            let mut case =
                Case { index: cases.len(), id: String::new(), params, varied: case_varied };
            case.id = case_id(&case.definition());
            cases.push(case);
        }
    }
    Ok(Manifest { path: PathBuf::new(), name, cases, varied })
}

fn unknown(key: &str, table: &str) -> ManifestError {
    bad(format!("unknown key `{key}` in {table} (known: {})", key_names().join(", ")))
}

/// The id of a case definition: the first 12 hex digits of the SHA-256 of its canonical JSON
/// (object keys sorted; serde_json's map keeps them sorted) behind a format tag.
pub fn case_id(definition: &Value) -> String {
    let mut h = Sha256::new();
    h.update(b"hitl-campaign-case-v1\n");
    h.update(definition.to_string().as_bytes());
    h.finalize().iter().take(6).map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_ok(text: &str) -> Manifest {
        parse(text, Path::new("/m"), "m").expect("manifest")
    }

    #[test]
    fn cases_are_the_product_in_key_order_whatever_the_file_order() {
        let a = parse_ok(
            "[run]\nduration_s = 4\n[matrix]\ntarget = [\"asymmetric\", \"one-plane\"]\nrange_m = [5, 10]\n",
        );
        let b = parse_ok(
            "[matrix]\nrange_m = [5, 10]\ntarget = [\"asymmetric\", \"one-plane\"]\n[run]\nduration_s = 4.0\n",
        );
        assert_eq!(a.cases.len(), 4);
        let order: Vec<(f64, String)> = a
            .cases
            .iter()
            .map(|c| (c.number("range_m").unwrap_or(0.0), c.cell("target")))
            .collect();
        assert_eq!(
            order,
            vec![
                (5.0, "asymmetric".into()),
                (5.0, "one-plane".into()),
                (10.0, "asymmetric".into()),
                (10.0, "one-plane".into())
            ]
        );
        let ids_a: Vec<&str> = a.cases.iter().map(|c| c.id.as_str()).collect();
        let ids_b: Vec<&str> = b.cases.iter().map(|c| c.id.as_str()).collect();
        assert_eq!(ids_a, ids_b, "integer 4 and float 4.0 are the same definition");
        assert_eq!(a.varied, vec!["range_m", "target"]);
        assert_eq!(a.cases[0].cell("perception"), "icp", "defaults filled in");
        let mut unique = ids_a.clone();
        unique.dedup();
        assert_eq!(unique.len(), 4);
    }

    #[test]
    fn matrix_tables_concatenate() {
        let m = parse_ok(
            "[[matrix]]\ncamera_preset = [\"wfov\"]\nrange_m = [5, 50]\n\
             [[matrix]]\ncamera_preset = [\"nfov\"]\nrange_m = [100]\n",
        );
        let cells: Vec<String> = m
            .cases
            .iter()
            .map(|c| format!("{}@{}", c.cell("camera_preset"), c.cell("range_m")))
            .collect();
        assert_eq!(cells, vec!["wfov@5", "wfov@50", "nfov@100"]);
        assert_eq!(m.cases[2].index, 2);
    }

    #[test]
    fn bad_manifests_name_the_key() {
        let e = |t: &str| parse(t, Path::new("/m"), "m").expect_err("refused").0;
        assert!(e("[run]\nrange = 5\n").contains("`range`"));
        assert!(e("[matrix]\nwarp_factor = [1]\n").contains("`warp_factor`"));
        assert!(e("[matrix]\nrange_m = 5\n").contains("list"));
        assert!(e("[run]\nrange_m = -5\n").contains("`range_m`"));
        assert!(e("[run]\nmesh_faces = 2\n").contains("`mesh_faces`"));
        assert!(e("[run]\nsun_phase_deg = \"a:b\"\n").contains("`sun_phase_deg`"));
        assert!(e("[run]\nrange_m = 5\n[matrix]\nrange_m = [5]\n").contains("both"));
        assert!(e("[matrix]\nconfig = [\"a.toml\"]\n").contains("`config`"));
        assert!(e("[extra]\n").contains("`extra`"));
    }

    #[test]
    fn ids_change_with_the_definition() {
        let a = parse_ok("[run]\nrange_m = 5\n");
        let b = parse_ok("[run]\nrange_m = 5\nmesh_faces = 100\n");
        assert_eq!(a.cases.len(), 1);
        assert_ne!(a.cases[0].id, b.cases[0].id);
        assert_eq!(a.cases[0].id.len(), 12);
        assert_eq!(b.cases[0].mesh_faces(), Some(100));
        assert_eq!(a.cases[0].mesh_faces(), None);
    }
}
