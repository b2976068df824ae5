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
    /// `FROM:TO` degrees with 0 <= FROM < TO <= 180: a region of unsigned Sun phase angle.
    PhaseRegion,
    /// An integer face budget, or "full" for the ground-truth mesh as it is.
    Faces,
    /// A path, resolved relative to the manifest's folder (`[run]` only).
    File,
    /// A SCHED_FIFO priority, 0 (the normal scheduler) to 99 (`[run]` only).
    Priority,
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
    KeyDef { name: "phase_angle_deg", kind: Kind::PhaseRegion, default: None, matrix: true },
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
    KeyDef { name: "rt_priority", kind: Kind::Priority, default: None, matrix: false },
    // The run's clock (`hitl run --clock`): simulated by default, so a case repeats exactly and
    // plays as fast as the machine allows; `realtime` still available (docs/sim-clock.md).
    KeyDef { name: "clock", kind: Kind::Text, default: Some(|| json!("sim")), matrix: false },
];

/// The highest SCHED_FIFO priority Linux grants (`hitl run` clamps its `--rt-priority` to 1-99
/// in `rt::os::set_fifo_priority`; a manifest refuses what would be clamped).
pub const MAX_RT_PRIORITY: i64 = 99;

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

/// The most cases a manifest may define. Counted from the lists' lengths (with overflow checks)
/// before a single case is built, so a manifest that asks for more is refused at once, naming the
/// count. `list`, `run` and `slurm` all load through this limit.
pub const MAX_CASES: usize = 100_000;

/// The most bytes a manifest file may have (a manifest within [`MAX_CASES`] is a few kilobytes).
pub const MAX_MANIFEST_BYTES: u64 = 1 << 20;

/// One matrix table: its keys (in [`KEYS`] order) and their lists.
type Axes = Vec<(&'static KeyDef, Vec<Value>)>;

/// A parsed manifest. Its cases are built on demand from the index (mixed radix over one matrix
/// table's lists), so neither `run --index I` nor `list` ever holds the whole grid.
#[derive(Clone)]
pub struct Manifest {
    pub path: PathBuf,
    pub name: String,
    /// The keys any matrix table varies, in key order.
    pub varied: Vec<String>,
    fixed: BTreeMap<&'static str, Value>,
    tables: Vec<Axes>,
    /// Cases per matrix table.
    counts: Vec<usize>,
    len: usize,
}

impl fmt::Debug for Manifest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Manifest")
            .field("path", &self.path)
            .field("name", &self.name)
            .field("cases", &self.len)
            .field("varied", &self.varied)
            .finish()
    }
}

impl Manifest {
    /// How many cases the manifest defines (at most [`MAX_CASES`]).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it defines no case (never, for a manifest that loaded).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Case `index` (0-based), built from its position alone; `None` past the last case.
    pub fn case(&self, index: usize) -> Option<Case> {
        let mut rest = index;
        for (axes, &count) in self.tables.iter().zip(&self.counts) {
            if rest >= count {
                rest -= count;
                continue;
            }
            // Mixed radix, the last axis fastest.
            let mut pick = vec![0usize; axes.len()];
            for (slot, (_, vals)) in pick.iter_mut().zip(axes.iter()).rev() {
                *slot = rest % vals.len();
                rest /= vals.len();
            }
            let chosen: Vec<(&'static str, &Value)> =
                axes.iter().zip(&pick).map(|((d, vals), &i)| (d.name, &vals[i])).collect();
            let mut case = self.case_from(&chosen);
            case.index = index;
            return Some(case);
        }
        None
    }

    /// Every case in order, each built when it is reached.
    pub fn cases(&self) -> impl Iterator<Item = Case> + '_ {
        (0..self.len).filter_map(|i| self.case(i))
    }

    /// A case with the `chosen` matrix values, the [run] values and the defaults (index 0).
    fn case_from(&self, chosen: &[(&'static str, &Value)]) -> Case {
        let mut params = BTreeMap::new();
        for def in KEYS {
            let v = chosen
                .iter()
                .find(|(k, _)| *k == def.name)
                .map(|(_, v)| (*v).clone())
                .or_else(|| self.fixed.get(def.name).cloned())
                .or_else(|| def.default.map(|f| f()));
            if let Some(v) = v {
                params.insert(def.name.to_string(), v);
            }
        }
        let varied = chosen.iter().map(|(k, _)| k.to_string()).collect();
        let mut case = Case { index: 0, id: String::new(), params, varied };
        case.id = case_id(&case.definition());
        case
    }

    /// The largest number `key` takes in any case (its [run] value or default where a matrix
    /// table does not vary it), without building the cases.
    pub fn max_number(&self, key: &str) -> Option<f64> {
        let base = self
            .fixed
            .get(key)
            .cloned()
            .or_else(|| key_def(key).and_then(|d| d.default.map(|f| f())));
        let mut best: Option<f64> = None;
        let mut take = |v: &Value| {
            if let Some(x) = v.as_f64() {
                best = Some(best.map_or(x, |b| b.max(x)));
            }
        };
        for axes in &self.tables {
            match axes.iter().find(|(d, _)| d.name == key) {
                Some((_, vals)) => vals.iter().for_each(&mut take),
                None => {
                    if let Some(v) = &base {
                        take(v);
                    }
                }
            }
        }
        best
    }

    /// A digest of everything the cases are made of (name, fixed values, every list): equal
    /// fingerprints, equal `cases.json`.
    pub fn fingerprint(&self) -> String {
        let tables: Vec<Value> = self
            .tables
            .iter()
            .map(|axes| Value::Array(axes.iter().map(|(d, v)| json!([d.name, v])).collect()))
            .collect();
        let all = json!({ "name": self.name, "fixed": self.fixed, "tables": tables });
        let mut h = Sha256::new();
        h.update(b"hitl-campaign-manifest-v1\n");
        h.update(all.to_string().as_bytes());
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }
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
        Kind::Priority => match v {
            toml::Value::Integer(i) if (0..=MAX_RT_PRIORITY).contains(i) => Ok(json!(*i)),
            _ => Err(bad(format!(
                "`{name}`: expected a SCHED_FIFO priority from 0 (the normal scheduler) to \
                 {MAX_RT_PRIORITY}, got {v}"
            ))),
        },
        Kind::Window => match v {
            toml::Value::String(s) => match parse_window(s) {
                Some((a, b)) => Ok(json!(format!("{a}:{b}"))),
                None => Err(bad(format!("`{name}`: expected \"FROM:TO\" in degrees, got {v}"))),
            },
            _ => Err(bad(format!("`{name}`: expected \"FROM:TO\" in degrees, got {v}"))),
        },
        Kind::PhaseRegion => match v {
            toml::Value::String(s) => match parse_window(s) {
                Some((a, b)) if (0.0..b).contains(&a) && b <= 180.0 => {
                    Ok(json!(format!("{a}:{b}")))
                }
                _ => Err(bad(format!(
                    "`{name}`: expected \"FROM:TO\", degrees of phase angle with 0 <= FROM < TO \
                     <= 180, got {v}"
                ))),
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

/// Read a manifest file (at most [`MAX_MANIFEST_BYTES`]) and check it.
pub fn load(path: &Path) -> Result<Manifest, ManifestError> {
    let bytes = super::store::read_capped(path, MAX_MANIFEST_BYTES)
        .map_err(|e| bad(format!("{}: {e}", path.display())))?;
    let text =
        String::from_utf8(bytes).map_err(|_| bad(format!("{}: not UTF-8 text", path.display())))?;
    load_text(path, &text)
}

/// Check manifest `text` read from `path` (relative paths resolve against its folder, the name
/// defaults to its file name).
pub fn load_text(path: &Path, text: &str) -> Result<Manifest, ManifestError> {
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let base = if base.as_os_str().is_empty() { PathBuf::from(".") } else { base };
    let base = std::fs::canonicalize(&base).unwrap_or(base);
    let default_name =
        path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    parse(text, &base, &default_name)
        .map(|mut m| {
            m.path = path.to_path_buf();
            m
        })
        .map_err(|e| bad(format!("{}: {e}", path.display())))
}

/// Longest campaign name, in bytes (it names the Slurm script and job).
pub const MAX_NAME_BYTES: usize = 100;

/// Why `name` cannot name a campaign: it becomes a file name under `--out` (the Slurm script)
/// and a job name, so it must stay one plain path component.
pub fn name_problem(name: &str) -> Option<String> {
    if name.is_empty() {
        Some("is empty".into())
    } else if name.len() > MAX_NAME_BYTES {
        Some(format!("is longer than {MAX_NAME_BYTES} bytes"))
    } else if name.contains(['/', '\\']) {
        Some("contains a path separator".into())
    } else if name.contains("..") || name.starts_with('.') {
        Some("starts with a dot or contains `..`".into())
    } else if name.chars().any(char::is_control) {
        Some("contains a control character (newline, tab, ...)".into())
    } else {
        None
    }
}

/// How many cases `tables` define, or `None` past `usize` (checked products and sum).
fn count_cases(tables: &[Axes]) -> Option<(Vec<usize>, usize)> {
    let counts: Vec<usize> = tables
        .iter()
        .map(|axes| axes.iter().try_fold(1usize, |n, (_, v)| n.checked_mul(v.len())))
        .collect::<Option<_>>()?;
    let total = counts.iter().try_fold(0usize, |n, &c| n.checked_add(c))?;
    Some((counts, total))
}

/// One [matrix] table's lists, each checked: a key that may vary, a list of distinct values.
fn matrix_axes(t: &toml::Table, base: &Path) -> Result<Axes, ManifestError> {
    let mut axes = Vec::new();
    for (k, v) in t {
        let def = key_def(k).ok_or_else(|| unknown(k, "[matrix]"))?;
        if !def.matrix {
            return Err(bad(format!(
                "`{k}` is fixed for a campaign: put it in [run], not [matrix]"
            )));
        }
        let list = v
            .as_array()
            .ok_or_else(|| bad(format!("[matrix] `{k}`: expected a list of values, got {v}")))?;
        if list.is_empty() {
            return Err(bad(format!("[matrix] `{k}`: the list is empty")));
        }
        let vals: Vec<Value> =
            list.iter().map(|x| value(def, x, base)).collect::<Result<_, _>>()?;
        let mut seen = std::collections::HashSet::new();
        if let Some(dup) = vals.iter().find(|v| !seen.insert(v.to_string())) {
            return Err(bad(format!("[matrix] `{k}` lists {dup} twice (two cases would be one)")));
        }
        axes.push((def, vals));
    }
    Ok(axes)
}

/// Check manifest text and count its cases (none is built); relative paths resolve against
/// `base`. Every value is checked with the parsers of the `hitl plan` / `hitl run` flag it
/// becomes ([`super::check`]), each against the defaults, once per distinct value.
pub fn parse(text: &str, base: &Path, default_name: &str) -> Result<Manifest, ManifestError> {
    let doc: toml::Table = text.parse().map_err(|e: toml::de::Error| bad(e.to_string()))?;
    let mut name = default_name.to_string();
    let mut fixed: BTreeMap<&'static str, Value> = BTreeMap::new();
    let mut tables: Vec<Axes> = Vec::new();
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
                    let text = v
                        .as_str()
                        .ok_or_else(|| bad(format!("[campaign] `{k}` must be a string")))?;
                    if k == "name" {
                        name = text.to_string();
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
                let list: Vec<&toml::Table> = match v {
                    toml::Value::Table(t) => vec![t],
                    toml::Value::Array(a) => a
                        .iter()
                        .map(|t| t.as_table().ok_or_else(|| bad("[[matrix]] must hold tables")))
                        .collect::<Result<_, _>>()?,
                    _ => return Err(bad("`matrix` must be a table ([matrix] or [[matrix]])")),
                };
                for t in list {
                    if t.is_empty() {
                        return Err(bad(format!(
                            "[matrix] table {} has no lists (give it keys or remove it)",
                            tables.len() + 1
                        )));
                    }
                    let mut axes = matrix_axes(t, base)?;
                    axes.sort_by_key(|(d, _)| KEYS.iter().position(|k| k.name == d.name));
                    tables.push(axes);
                }
            }
            other => {
                return Err(bad(format!(
                    "unknown table `{other}` (a manifest has [campaign], [run] and [matrix])"
                )))
            }
        }
    }
    if !doc.contains_key("run") && !doc.contains_key("matrix") {
        return Err(bad(
            "no [run] or [matrix] table: the manifest defines no case (an empty manifest is \
             refused rather than played as one default case)",
        ));
    }
    if let Some(why) = name_problem(&name) {
        return Err(bad(format!(
            "campaign name {name:?} {why}: it names files under --out; give [campaign] `name` \
             as one plain file name"
        )));
    }
    for axes in &tables {
        if let Some((d, _)) = axes.iter().find(|(d, _)| fixed.contains_key(d.name)) {
            return Err(bad(format!(
                "`{}` is in both [run] and [matrix]: give it in one place",
                d.name
            )));
        }
    }
    if tables.is_empty() {
        tables.push(Vec::new());
    }
    // Count before anything is built or checked further: a grid past the limit is refused at once.
    let (counts, len) = match count_cases(&tables) {
        Some((counts, len)) if len <= MAX_CASES => (counts, len),
        Some((_, len)) => {
            return Err(bad(format!(
                "{len} cases (the product of the [matrix] lists), more than the limit of \
                 {MAX_CASES}: split the study into several manifests"
            )))
        }
        None => {
            return Err(bad(format!(
                "more than {} cases (the product of the [matrix] lists overflows), more than \
                 the limit of {MAX_CASES}: split the study into several manifests",
                usize::MAX
            )))
        }
    };
    let mut varied: Vec<String> = Vec::new();
    for def in KEYS {
        if tables.iter().any(|axes| axes.iter().any(|(d, _)| d.name == def.name)) {
            varied.push(def.name.to_string());
        }
    }
    let m = Manifest { path: PathBuf::new(), name, varied, fixed, tables, counts, len };
    check_values(&m)?;
    Ok(m)
}

/// Every value, alone against the defaults (and the manifest's `config`), through the parsers of
/// the flags it becomes; each distinct value once.
fn check_values(m: &Manifest) -> Result<(), ManifestError> {
    let config = m.fixed.get("config").and_then(Value::as_str);
    let checker = super::check::Checker::new(config).map_err(|e| bad(format!("`config`: {e}")))?;
    let probe = |key: &'static str, v: &Value| {
        let mut params: BTreeMap<String, Value> =
            KEYS.iter().filter_map(|d| d.default.map(|f| (d.name.to_string(), f()))).collect();
        if let Some(c) = m.fixed.get("config") {
            params.insert("config".into(), c.clone());
        }
        params.insert(key.to_string(), v.clone());
        Case { index: 0, id: String::new(), params, varied: Vec::new() }
    };
    for (key, v) in &m.fixed {
        checker.check(key, &probe(key, v)).map_err(|e| bad(format!("[run] `{key}` = {v}: {e}")))?;
    }
    let mut seen = std::collections::HashSet::new();
    for axes in &m.tables {
        for (def, vals) in axes {
            for v in vals {
                if seen.insert((def.name, v.to_string())) {
                    checker
                        .check(def.name, &probe(def.name, v))
                        .map_err(|e| bad(format!("[matrix] `{}` = {v}: {e}", def.name)))?;
                }
            }
        }
    }
    Ok(())
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

    fn all(m: &Manifest) -> Vec<Case> {
        m.cases().collect()
    }

    #[test]
    fn cases_are_the_product_in_key_order_whatever_the_file_order() {
        let a = parse_ok(
            "[run]\nduration_s = 4\n[matrix]\ntarget = [\"asymmetric\", \"one-plane\"]\nrange_m = [5, 10]\n",
        );
        let b = parse_ok(
            "[matrix]\nrange_m = [5, 10]\ntarget = [\"asymmetric\", \"one-plane\"]\n[run]\nduration_s = 4.0\n",
        );
        let (a, b) = (all(&a), all(&b));
        assert_eq!(a.len(), 4);
        let order: Vec<(f64, String)> =
            a.iter().map(|c| (c.number("range_m").unwrap_or(0.0), c.cell("target"))).collect();
        assert_eq!(
            order,
            vec![
                (5.0, "asymmetric".into()),
                (5.0, "one-plane".into()),
                (10.0, "asymmetric".into()),
                (10.0, "one-plane".into())
            ]
        );
        let ids_a: Vec<&str> = a.iter().map(|c| c.id.as_str()).collect();
        let ids_b: Vec<&str> = b.iter().map(|c| c.id.as_str()).collect();
        assert_eq!(ids_a, ids_b, "integer 4 and float 4.0 are the same definition");
        assert_eq!(a[0].varied, vec!["range_m", "target"]);
        assert_eq!(a[0].cell("perception"), "icp", "defaults filled in");
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
        let cases = all(&m);
        let cells: Vec<String> = cases
            .iter()
            .map(|c| format!("{}@{}", c.cell("camera_preset"), c.cell("range_m")))
            .collect();
        assert_eq!(cells, vec!["wfov@5", "wfov@50", "nfov@100"]);
        assert_eq!(cases[2].index, 2);
        assert_eq!(m.case(2), Some(cases[2].clone()), "built from its index alone");
        assert_eq!(m.case(3), None);
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
        // A phase angle is 0-180 deg, FROM below TO.
        for bad in ["\"170:190\"", "\"36:0\"", "\"-1:36\"", "36"] {
            let m = format!("[run]\nphase_angle_deg = {bad}\n");
            assert!(e(&m).contains("`phase_angle_deg`"), "{bad}");
        }
        assert!(e("[run]\nrange_m = 5\n[matrix]\nrange_m = [5]\n").contains("both"));
        assert!(e("[matrix]\nconfig = [\"a.toml\"]\n").contains("`config`"));
        assert!(e("[extra]\n").contains("`extra`"));
    }

    #[test]
    fn ids_change_with_the_definition() {
        let a = parse_ok("[run]\nrange_m = 5\n");
        let b = parse_ok("[run]\nrange_m = 5\nmesh_faces = 100\n");
        let (a, b) = (all(&a), all(&b));
        assert_eq!(a.len(), 1);
        assert_ne!(a[0].id, b[0].id);
        assert_eq!(a[0].id.len(), 12);
        assert_eq!(b[0].mesh_faces(), Some(100));
        assert_eq!(a[0].mesh_faces(), None);
    }

    #[test]
    fn grids_past_the_limit_are_refused_before_any_case_is_built() {
        let e = |t: &str| parse(t, Path::new("/m"), "m").expect_err("refused").0;
        let list = |n: usize| {
            let v: Vec<String> = (1..=n).map(|i| i.to_string()).collect();
            format!("[{}]", v.join(", "))
        };
        // 10^6: six axes of ten values.
        let million = format!(
            "[matrix]\nrange_m = {l}\nduration_s = {l}\nmesh_faces = {f}\nreregister_every = \
             {l}\ncapture_every_s = {l}\ntarget = {t}\n",
            l = list(10),
            f = "[10, 11, 12, 13, 14, 15, 16, 17, 18, 19]",
            t = "[\"a\", \"b\", \"c\", \"d\", \"e\", \"f\", \"g\", \"h\", \"i\", \"j\"]",
        );
        let msg = e(&million);
        assert!(msg.contains("1000000 cases") && msg.contains("100000"), "{msg}");
        // Past usize: every matrix key with 40 values (40^13 > 2^64), counted, not built.
        let mut huge = String::from("[matrix]\n");
        for def in KEYS.iter().filter(|d| d.matrix) {
            let vals: Vec<String> = (0..40)
                .map(|i| match def.kind {
                    Kind::Text => format!("\"v{i}\""),
                    Kind::Window => format!("\"{i}:{}\"", i + 10),
                    Kind::PhaseRegion => format!("\"{i}:{}\"", i + 100),
                    _ => format!("{}", i + 4),
                })
                .collect();
            huge += &format!("{} = [{}]\n", def.name, vals.join(", "));
        }
        let msg = e(&huge);
        assert!(msg.contains("overflows") && msg.contains("100000"), "{msg}");
        // At the limit exactly: accepted, and its last case is built from its index alone.
        let at = format!(
            "[matrix]\nrange_m = {l}\nduration_s = {l}\nreregister_every = {l}\n\
             capture_every_s = {l}\nmesh_faces = {f}\n",
            l = list(10),
            f = "[10, 11, 12, 13, 14, 15, 16, 17, 18, 19]",
        );
        let m = parse_ok(&at);
        assert_eq!(m.len(), MAX_CASES);
        let last = m.case(MAX_CASES - 1).expect("last case");
        assert_eq!(last.cell("range_m"), "10");
        assert_eq!(last.cell("mesh_faces"), "19");
        assert!(m.case(MAX_CASES).is_none());
        assert_eq!(m.max_number("duration_s"), Some(10.0));
    }

    #[test]
    fn counting_overflows_are_caught() {
        let def = &KEYS[4];
        let axis = (def, vec![json!(1); 1 << 20]);
        let tables: Vec<Axes> = vec![vec![axis.clone(), axis.clone(), axis.clone(), axis.clone()]];
        assert_eq!(count_cases(&tables), None, "2^80 cases");
        let tables: Vec<Axes> = vec![vec![axis.clone(), axis.clone(), axis.clone()]; 1 << 5];
        assert_eq!(count_cases(&tables), None, "32 tables of 2^60");
        let tables: Vec<Axes> = vec![vec![axis.clone()], vec![]];
        assert_eq!(count_cases(&tables).map(|(_, n)| n), Some((1 << 20) + 1));
    }

    #[test]
    fn empty_manifests_and_bad_names_are_refused() {
        let e = |t: &str| parse(t, Path::new("/m"), "m").expect_err("refused").0;
        assert!(e("").contains("no [run] or [matrix]"));
        assert!(e("[campaign]\nname = \"x\"\n").contains("no [run] or [matrix]"));
        assert!(e("[matrix]\n").contains("no lists"));
        for name in ["../../../escaped", "a/b", "a\\nb", "..", ".hidden", "tab\\there"] {
            let msg = e(&format!("[campaign]\nname = \"{name}\"\n[run]\nrange_m = 5\n"));
            assert!(msg.contains("campaign name"), "{name}: {msg}");
        }
        assert!(e("[matrix]\nrange_m = [5, 5.0]\n").contains("twice"));
        assert!(parse(
            "[campaign]\nname = \"rq3 range v2\"\n[run]\nrange_m = 5\n",
            Path::new("/m"),
            "m"
        )
        .is_ok());
    }

    #[test]
    fn values_are_checked_by_the_flags_parsers() {
        let e = |t: &str| parse(t, Path::new("/m"), "m").expect_err("refused").0;
        for (text, key, says) in [
            ("[run]\ncamera_size = \"0x0\"\n", "camera_size", "--camera-size"),
            ("[run]\npreset = \"warp\"\n", "preset", "--preset"),
            ("[run]\nscene_kind = \"moon\"\n", "scene_kind", "--scene-kind"),
            ("[matrix]\nperception = [\"icp\", \"magic\"]\n", "perception", "--perception"),
            ("[run]\ncamera_preset = \"xfov\"\n", "camera_preset", "--camera-preset"),
            ("[run]\nrt_priority = -1\n", "rt_priority", "0"),
            ("[run]\nrt_priority = 1000\n", "rt_priority", "99"),
            ("[run]\nreregister_every = 0\n", "reregister_every", "at least 1"),
            ("[matrix]\narc_deg = [\"10:10\"]\n", "arc_deg", "--arc"),
            ("[run]\nduration_s = 1e300\n", "duration_s", "waypoints"),
            ("[run]\nrange_m = 1e9\n", "range_m", "--range-m"),
        ] {
            let msg = e(text);
            assert!(msg.contains(&format!("`{key}`")) && msg.contains(says), "{text}: {msg}");
        }
        parse_ok("[run]\nrt_priority = 0\nreregister_every = 5\ncamera_size = \"96x64\"\n");
    }

    proptest::proptest! {
        /// Any text: parsed or refused, never a panic.
        #[test]
        fn any_text_is_parsed_or_refused(text in "\\PC{0,200}") {
            let _ = parse(&text, Path::new("/m"), "m");
        }

        /// Manifest-shaped text with arbitrary keys and values: parsed or refused, never a
        /// panic; a parsed one has at most MAX_CASES cases, each built from its index.
        #[test]
        fn manifest_shaped_text_is_parsed_or_refused(
            run in proptest::collection::vec((0usize..KEYS.len() + 1, "[-a-z0-9.:x\"]{0,8}|[0-9]{1,3}|-?[0-9]+\\.[0-9]+e[0-9]{1,3}"), 0..4),
            matrix in proptest::collection::vec(
                proptest::collection::vec((0usize..KEYS.len() + 1, proptest::collection::vec("\"[a-z0-9:x.-]{0,6}\"|[0-9]{1,4}|-?[0-9]\\.[0-9]", 0..4)), 0..3),
                0..3),
        ) {
            let key = |i: usize| KEYS.get(i).map_or("bogus", |k| k.name);
            let mut text = String::from("[run]\n");
            for (k, v) in &run {
                text += &format!("{} = {v}\n", key(*k));
            }
            for t in &matrix {
                text += "[[matrix]]\n";
                for (k, vals) in t {
                    text += &format!("{} = [{}]\n", key(*k), vals.join(", "));
                }
            }
            if let Ok(m) = parse(&text, Path::new("/m"), "m") {
                proptest::prop_assert!(m.len() <= MAX_CASES && !m.is_empty());
                proptest::prop_assert!(m.case(m.len() - 1).is_some());
                proptest::prop_assert!(m.case(m.len()).is_none());
            }
        }
    }
}
