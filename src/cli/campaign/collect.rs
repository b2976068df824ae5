//! `hitl campaign collect DIR`: one row per case of the folder's manifest (DIR/cases.json) in
//! DIR/results.csv: index, id, status, every run parameter, then the paper's metrics of the
//! estimator (frames, failures, mean/median/temporal standard deviation of e_t in real metres and
//! e_r in degrees) and the same of the run's own estimates with the ground-truth mesh (`gt_*`,
//! the baseline; equal to the first set when the case decimates nothing). Also the paper's plots
//! (see [`super::plots`]) under DIR/plots/, and a Markdown table on stdout.
//!
//! Nothing is taken on trust: a `result.json` is read only if it is a regular file (not a link,
//! device or FIFO) of at most [`store::MAX_RESULT_BYTES`], and only if every value in it is one
//! the campaign writes (a known status, counts that are whole and non-negative, errors that are
//! finite and in range). Anything else makes the case `corrupt`, with the reason in the
//! `problem` column and on stderr, and none of its values reach the table.

use super::manifest::{case_id, key_names};
use super::store::{self, write_atomic};
use crate::exit;
use serde_json::Value;
use std::path::Path;

/// Metric columns, in order: the eval JSON's keys. The paper's figures, then the same up to the
/// target's declared symmetry (`*_sym_*`, never above the paper's e_r; results written before
/// they existed leave those cells empty).
pub const METRICS: [&str; 14] = [
    "frames",
    "failures",
    "mean_et_m",
    "median_et_m",
    "std_et_m",
    "mean_er_deg",
    "median_er_deg",
    "std_er_deg",
    "mean_et_sym_m",
    "median_et_sym_m",
    "std_et_sym_m",
    "mean_er_sym_deg",
    "median_er_sym_deg",
    "std_er_sym_deg",
];

/// One collected case.
#[derive(Debug, Clone)]
pub struct Row {
    pub index: usize,
    pub id: String,
    /// ok, failed, missing (not played yet) or corrupt (a result that cannot be trusted).
    pub status: String,
    /// Why a corrupt result is corrupt.
    pub problem: Option<String>,
    pub definition: Value,
    pub varied: Vec<String>,
    /// The estimator's metrics (eval.json) and the ground-truth-mesh baseline (eval-gt.json).
    pub metrics: Option<Value>,
    pub baseline: Option<Value>,
    pub result: Option<Value>,
}

impl Row {
    pub fn param(&self, key: &str) -> Option<&Value> {
        self.definition.get(key)
    }

    pub fn param_text(&self, key: &str) -> String {
        match self.param(key) {
            None | Some(Value::Null) => String::new(),
            Some(Value::String(s)) => s.clone(),
            Some(v) => v.as_f64().map_or_else(|| v.to_string(), |x| format!("{x}")),
        }
    }

    pub fn metric(&self, key: &str) -> Option<f64> {
        self.metrics.as_ref()?.get(key)?.as_f64()
    }

    pub fn baseline_metric(&self, key: &str) -> Option<f64> {
        self.baseline.as_ref()?.get(key)?.as_f64()
    }
}

/// Exit code of `collect` when it wrote the table but some results are corrupt.
pub const CORRUPT_RESULTS: u8 = 1;

/// Why `v` is not a metrics object as `hitl eval --json` writes it.
fn metrics_problem(v: Option<&Value>) -> Option<String> {
    let Some(m) = v.and_then(Value::as_object) else {
        return Some("no metrics object".into());
    };
    let count = |k: &str| match m.get(k) {
        Some(x) => x.as_u64().ok_or_else(|| format!("{k} = {x} is not a whole number >= 0")),
        None => Err(format!("no {k}")),
    };
    let frames = match count("frames") {
        Ok(n) => n,
        Err(e) => return Some(e),
    };
    match count("failures") {
        Ok(f) if f > frames => return Some(format!("failures = {f} > frames = {frames}")),
        Ok(_) => {}
        Err(e) => return Some(e),
    }
    for k in &METRICS[2..] {
        let max = if k.ends_with("_deg") { 180.0 } else { f64::INFINITY };
        match m.get(*k) {
            None | Some(Value::Null) => {}
            Some(x) => match x.as_f64() {
                Some(f) if f.is_finite() && (0.0..=max).contains(&f) => {}
                _ => return Some(format!("{k} = {x} is out of range (0 to {max})")),
            },
        }
    }
    for k in ["mean_er", "median_er"] {
        let plain = m.get(&format!("{k}_deg")).and_then(Value::as_f64);
        let sym = m.get(&format!("{k}_sym_deg")).and_then(Value::as_f64);
        if let (Some(p), Some(s)) = (plain, sym) {
            if s > p + 1e-9 {
                return Some(format!("{k}_sym_deg = {s} is above {k}_deg = {p}"));
            }
        }
    }
    if let Some(x) = m.get("symmetry").filter(|x| !x.is_null() && !x.is_string()) {
        return Some(format!("symmetry = {x} is not a declaration"));
    }
    if let Some(x) = m.get("mesh_faces").filter(|x| !x.is_null() && x.as_u64().is_none()) {
        return Some(format!("mesh_faces = {x} is not a whole number >= 0"));
    }
    None
}

/// The status of a parsed `result.json` of case `id`, or why it cannot be trusted.
pub(super) fn check_result(r: &Value, id: &str, definition: &Value) -> Result<String, String> {
    if !r.is_object() {
        return Err("not a JSON object".into());
    }
    if r.get("id").and_then(Value::as_str) != Some(id) || r.get("definition") != Some(definition) {
        return Err("made for another case (its id or definition differ)".into());
    }
    let status = match r.get("status") {
        Some(Value::String(s)) if s == "ok" || s == "failed" => s.clone(),
        Some(x) => return Err(format!("unknown status {x} (ok or failed)")),
        None => return Err("no status".into()),
    };
    if status == "ok" {
        if let Some(why) = metrics_problem(r.get("metrics")) {
            return Err(format!("metrics: {why}"));
        }
        if let Some(why) = metrics_problem(r.get("baseline")) {
            return Err(format!("baseline: {why}"));
        }
    } else {
        if !r.get("failed_stage").is_some_and(Value::is_string) {
            return Err("a failed case without its failed_stage".into());
        }
        if let Some(x) = r.get("exit_code").filter(|x| !x.is_null() && x.as_i64().is_none()) {
            return Err(format!("exit_code = {x} is not an integer"));
        }
    }
    if let Some(x) = r.get("wall_s") {
        if !x.as_f64().is_some_and(|w| w.is_finite() && w >= 0.0) {
            return Err(format!("wall_s = {x} is not a duration"));
        }
    }
    match r.get("planned_sun_phase_deg") {
        None | Some(Value::Null) => {}
        Some(Value::Array(a))
            if a.len() == 2 && a.iter().all(|x| x.as_f64().is_some_and(f64::is_finite)) => {}
        Some(x) => return Err(format!("planned_sun_phase_deg = {x} is not [min, max]")),
    }
    if let Some(x) = r.get("arc_deg").filter(|x| !x.is_null() && !x.is_string()) {
        return Err(format!("arc_deg = {x} is not \"FROM:TO\""));
    }
    Ok(status)
}

/// A case's result as collect takes it: (status, the result if trusted, why not).
fn read_case(dir: &Path, id: &str, definition: &Value) -> (String, Option<Value>, Option<String>) {
    let corrupt = |why: String| ("corrupt".to_string(), None, Some(why));
    let bytes = match store::read_regular(&store::result_path(dir, id), store::MAX_RESULT_BYTES) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return ("missing".into(), None, None)
        }
        Err(e) => return corrupt(format!("result.json: {e}")),
    };
    let r: Value = match serde_json::from_slice(&bytes) {
        Ok(r) => r,
        Err(e) => return corrupt(format!("result.json is not JSON (truncated?): {e}")),
    };
    match check_result(&r, id, definition) {
        Ok(status) => (status, Some(r), None),
        Err(why) => corrupt(format!("result.json: {why}")),
    }
}

/// Read the folder's cases and their results.
pub fn rows(dir: &Path) -> Result<Vec<Row>, String> {
    let index_path = dir.join("cases.json");
    let bytes = store::read_regular(&index_path, store::MAX_INDEX_BYTES).map_err(|e| {
        format!(
            "{}: {e} (not a campaign folder: run `hitl campaign run M.toml --out DIR` first)",
            index_path.display()
        )
    })?;
    let index: Value =
        serde_json::from_slice(&bytes).map_err(|e| format!("{}: {e}", index_path.display()))?;
    drop(bytes);
    let varied: Vec<String> = index
        .get("varied")
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(|v| v.as_str().map(str::to_string)).collect())
        .unwrap_or_default();
    let cases = index
        .get("cases")
        .and_then(Value::as_array)
        .ok_or_else(|| format!("{}: no `cases` list", index_path.display()))?;
    let mut rows = Vec::new();
    for c in cases {
        let id = c.get("id").and_then(Value::as_str).unwrap_or_default().to_string();
        let definition = c.get("definition").cloned().unwrap_or(Value::Null);
        if case_id(&definition) != id {
            return Err(format!(
                "{}: case {id} does not match its definition",
                index_path.display()
            ));
        }
        let (status, result, problem) = read_case(dir, &id, &definition);
        rows.push(Row {
            index: c.get("index").and_then(Value::as_u64).unwrap_or(rows.len() as u64) as usize,
            id,
            status,
            problem,
            definition,
            varied: varied.clone(),
            metrics: result
                .as_ref()
                .and_then(|r| r.get("metrics").cloned())
                .filter(|m| m.is_object()),
            baseline: result
                .as_ref()
                .and_then(|r| r.get("baseline").cloned())
                .filter(|m| m.is_object()),
            result,
        });
    }
    rows.sort_by_key(|r| r.index);
    Ok(rows)
}

/// A CSV field, quoted when it must be.
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn num(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

/// The CSV text of `rows`.
pub fn csv(rows: &[Row]) -> String {
    let keys = key_names();
    let mut header: Vec<String> = vec!["index".into(), "id".into(), "status".into()];
    header.extend(keys.iter().map(|k| k.to_string()));
    header.extend(METRICS.iter().map(|m| m.to_string()));
    header.extend(METRICS.iter().map(|m| format!("gt_{m}")));
    header.extend(
        [
            "planned_arc_deg",
            "planned_sun_phase_min_deg",
            "planned_sun_phase_max_deg",
            "mesh_faces_used",
            "symmetry",
            "wall_s",
            "real_time_factor",
            "failed_stage",
            "exit_code",
            "problem",
        ]
        .map(String::from),
    );
    let mut out = header.join(",");
    out.push('\n');
    for r in rows {
        let res = |k: &str| {
            r.result.as_ref().and_then(|x| x.get(k)).map_or(String::new(), |v| match v {
                Value::Null => String::new(),
                Value::String(s) => s.clone(),
                v => v.to_string(),
            })
        };
        let mut cells: Vec<String> = vec![r.index.to_string(), r.id.clone(), r.status.clone()];
        cells.extend(keys.iter().map(|k| r.param_text(k)));
        cells.extend(METRICS.iter().map(|m| num(r.metric(m))));
        cells.extend(METRICS.iter().map(|m| num(r.baseline_metric(m))));
        let faces = r.metrics.as_ref().and_then(|m| m.get("mesh_faces")).and_then(Value::as_u64);
        cells.push(res("arc_deg"));
        for k in 0..2 {
            let phase =
                r.result.as_ref().and_then(|x| x.pointer(&format!("/planned_sun_phase_deg/{k}")));
            cells.push(num(phase.and_then(Value::as_f64)));
        }
        cells.push(faces.map_or(String::new(), |f| f.to_string()));
        let symmetry = r.metrics.as_ref().and_then(|m| m.get("symmetry")).and_then(Value::as_str);
        cells.push(symmetry.unwrap_or_default().to_string());
        cells.push(res("wall_s"));
        cells.push(res("real_time_factor"));
        cells.push(res("failed_stage"));
        cells.push(res("exit_code"));
        cells.push(r.problem.clone().unwrap_or_default());
        out.push_str(&cells.iter().map(|c| field(c)).collect::<Vec<_>>().join(","));
        out.push('\n');
    }
    out
}

/// A Markdown table of the varied parameters and the headline metrics.
pub fn markdown(rows: &[Row]) -> String {
    let varied = rows.first().map(|r| r.varied.clone()).unwrap_or_default();
    let mut head: Vec<String> = varied.clone();
    head.extend(
        [
            "status",
            "frames",
            "failures",
            "mean e_t [m]",
            "median e_t [m]",
            "mean e_r [deg]",
            "median e_r [deg]",
            "mean e_r sym [deg]",
            "median e_r sym [deg]",
            "GT mean e_t [m]",
            "GT mean e_r [deg]",
            "e_t / range",
            "goal",
            "goal sym",
        ]
        .map(String::from),
    );
    let mut out = format!("| {} |\n|{}\n", head.join(" | "), " --- |".repeat(head.len()));
    let f = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |x| format!("{x:.d$}"));
    for r in rows {
        let mut cells: Vec<String> = varied.iter().map(|k| r.param_text(k)).collect();
        cells.push(r.status.clone());
        cells.push(f(r.metric("frames"), 0));
        cells.push(f(r.metric("failures"), 0));
        cells.push(f(r.metric("mean_et_m"), 4));
        cells.push(f(r.metric("median_et_m"), 4));
        cells.push(f(r.metric("mean_er_deg"), 2));
        cells.push(f(r.metric("median_er_deg"), 2));
        cells.push(f(r.metric("mean_er_sym_deg"), 2));
        cells.push(f(r.metric("median_er_sym_deg"), 2));
        cells.push(f(r.baseline_metric("mean_et_m"), 4));
        cells.push(f(r.baseline_metric("mean_er_deg"), 2));
        let (share, goal_plain) = goal(r, "mean_et_m", "mean_er_deg");
        cells.push(share);
        cells.push(goal_plain);
        cells.push(goal(r, "mean_et_sym_m", "mean_er_sym_deg").1);
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

/// The paper's accuracy goal for a row: mean e_t at most 1 % of the range and mean e_r at most
/// 1.5 deg, on the metrics `et` and `er` (the paper's, or the same up to symmetry). Returns e_t as
/// a share of the range and "met" / "missed" ("-" without a range or metrics, e.g. a failed
/// case).
fn goal(r: &Row, et: &str, er: &str) -> (String, String) {
    let range = r.param_text("range_m").parse::<f64>().ok().filter(|x| *x > 0.0);
    match (range, r.metric(et), r.metric(er)) {
        (Some(range), Some(et), Some(er)) => {
            let share = et / range;
            let met = share <= 0.01 && er <= 1.5;
            (format!("{:.3} %", 100.0 * share), if met { "met" } else { "missed" }.to_string())
        }
        _ => ("-".to_string(), "-".to_string()),
    }
}

/// Run `hitl campaign collect DIR`.
pub fn run(dir: &Path) -> u8 {
    let rows = match rows(dir) {
        Ok(r) => r,
        Err(e) => {
            crate::errln!("hitl campaign collect: {e}");
            return exit::BAD_INPUT;
        }
    };
    let csv_path = dir.join("results.csv");
    if let Err(e) = write_atomic(&csv_path, csv(&rows).as_bytes()) {
        crate::errln!("hitl campaign collect: {}: {e}", csv_path.display());
        return exit::BAD_INPUT;
    }
    crate::out!("{}", markdown(&rows));
    let count = |s: &str| rows.iter().filter(|r| r.status == s).count();
    let corrupt = count("corrupt");
    crate::outln!(
        "{} cases: {} ok, {} failed, {} not played, {corrupt} corrupt -> {}",
        rows.len(),
        count("ok"),
        count("failed"),
        count("missing"),
        csv_path.display()
    );
    for r in rows.iter().filter(|r| r.status == "corrupt") {
        crate::errln!(
            "hitl campaign collect: case {} [{}] is corrupt: {} (its row is empty; `hitl \
             campaign run` plays it again)",
            r.index,
            r.id,
            r.problem.as_deref().unwrap_or("?")
        );
    }
    match super::plots::write_all(&rows, &dir.join("plots")) {
        Ok(files) => {
            for f in files {
                crate::outln!("wrote {}", f.display());
            }
        }
        Err(e) => {
            crate::errln!("hitl campaign collect: plots: {e}");
            return exit::BAD_INPUT;
        }
    }
    if corrupt > 0 {
        CORRUPT_RESULTS
    } else {
        exit::OK
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_fields_are_quoted_when_needed() {
        assert_eq!(field("a"), "a");
        assert_eq!(field("a,b"), "\"a,b\"");
        assert_eq!(field("say \"x\""), "\"say \"\"x\"\"\"");
    }

    /// A two-planes row whose paper e_r misses the goal on flips the symmetric score forgives.
    fn flipped_row() -> Row {
        let metrics = serde_json::json!({
            "frames": 151, "failures": 0, "mean_et_m": 0.0084, "median_et_m": 0.008,
            "std_et_m": 0.002, "mean_er_deg": 42.48, "median_er_deg": 0.07, "std_er_deg": 76.0,
            "mean_et_sym_m": 0.0084, "median_et_sym_m": 0.008, "std_et_sym_m": 0.002,
            "mean_er_sym_deg": 0.09, "median_er_sym_deg": 0.07, "std_er_sym_deg": 0.05,
            "symmetry": "two-planes:z",
        });
        Row {
            index: 0,
            id: "abc".into(),
            status: "ok".into(),
            problem: None,
            definition: serde_json::json!({"range_m": 50.0, "target": "two-planes"}),
            varied: vec!["range_m".into(), "target".into()],
            metrics: Some(metrics.clone()),
            baseline: Some(metrics),
            result: None,
        }
    }

    #[test]
    fn tables_show_both_scores_and_both_goals() {
        let r = flipped_row();
        let md = markdown(std::slice::from_ref(&r));
        let head = md.lines().next().unwrap_or_default();
        assert!(head.contains("mean e_r sym [deg]") && head.contains("goal sym"), "{md}");
        let row = md.lines().nth(2).unwrap_or_default();
        assert!(row.contains("| 42.48 | 0.07 | 0.09 | 0.07 |"), "{row}");
        assert!(row.ends_with("| missed | met |"), "{row}");
        let csv = csv(std::slice::from_ref(&r));
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        let cells: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or(usize::MAX);
        assert_eq!(cells[col("mean_er_sym_deg")], "0.09");
        assert_eq!(cells[col("gt_mean_er_sym_deg")], "0.09");
        assert_eq!(cells[col("symmetry")], "two-planes:z");
    }

    #[test]
    fn a_symmetric_score_above_the_paper_s_is_corrupt() {
        let mut m = flipped_row().metrics.unwrap_or_default();
        assert_eq!(metrics_problem(Some(&m)), None);
        m["mean_er_sym_deg"] = serde_json::json!(50.0);
        let why = metrics_problem(Some(&m)).unwrap_or_default();
        assert!(why.contains("mean_er_sym_deg = 50 is above"), "{why}");
        m["mean_er_sym_deg"] = serde_json::json!(190.0);
        assert!(metrics_problem(Some(&m)).is_some());
    }
}
