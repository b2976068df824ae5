//! `hitl campaign collect DIR`: one row per case of the folder's manifest (DIR/cases.json) in
//! DIR/results.csv: index, id, status, every run parameter, then the paper's metrics of the
//! estimator (frames, failures, mean/median/temporal standard deviation of e_t in real metres and
//! e_r in degrees) and the same of the run's own estimates with the ground-truth mesh (`gt_*`,
//! the baseline; equal to the first set when the case decimates nothing). Also the paper's plots
//! (see [`super::plots`]) under DIR/plots/, and a Markdown table on stdout.

use super::manifest::{case_id, key_names};
use super::store::{self, write_atomic};
use crate::exit;
use serde_json::Value;
use std::path::Path;

/// Metric columns, in order: the eval JSON's keys.
pub const METRICS: [&str; 8] = [
    "frames",
    "failures",
    "mean_et_m",
    "median_et_m",
    "std_et_m",
    "mean_er_deg",
    "median_er_deg",
    "std_er_deg",
];

/// One collected case.
#[derive(Debug, Clone)]
pub struct Row {
    pub index: usize,
    pub id: String,
    /// ok, failed or missing (not played yet).
    pub status: String,
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

/// Read the folder's cases and their results.
pub fn rows(dir: &Path) -> Result<Vec<Row>, String> {
    let index_path = dir.join("cases.json");
    let text = std::fs::read_to_string(&index_path).map_err(|e| {
        format!(
            "{}: {e} (not a campaign folder: run `hitl campaign run M.toml --out DIR` first)",
            index_path.display()
        )
    })?;
    let index: Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", index_path.display()))?;
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
        let result =
            store::read_result(dir, &id).filter(|r| r.get("definition") == Some(&definition));
        let status = result
            .as_ref()
            .and_then(|r| r.get("status").and_then(Value::as_str))
            .unwrap_or("missing")
            .to_string();
        rows.push(Row {
            index: c.get("index").and_then(Value::as_u64).unwrap_or(rows.len() as u64) as usize,
            id,
            status,
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
            "wall_s",
            "failed_stage",
            "exit_code",
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
        cells.push(res("wall_s"));
        cells.push(res("failed_stage"));
        cells.push(res("exit_code"));
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
            "GT mean e_t [m]",
            "GT mean e_r [deg]",
            "e_t / range",
            "goal",
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
        cells.push(f(r.baseline_metric("mean_et_m"), 4));
        cells.push(f(r.baseline_metric("mean_er_deg"), 2));
        let (share, goal) = goal(r);
        cells.push(share);
        cells.push(goal);
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

/// The paper's accuracy goal for a row: mean e_t at most 1 % of the range and mean e_r at most
/// 1.5 deg. Returns e_t as a share of the range and "met" / "missed" ("-" without a range or
/// metrics, e.g. a failed case).
fn goal(r: &Row) -> (String, String) {
    let range = r.param_text("range_m").parse::<f64>().ok().filter(|x| *x > 0.0);
    match (range, r.metric("mean_et_m"), r.metric("mean_er_deg")) {
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
    let ok = rows.iter().filter(|r| r.status == "ok").count();
    crate::outln!(
        "{} cases: {ok} ok, {} failed, {} not played -> {}",
        rows.len(),
        rows.iter().filter(|r| r.status == "failed").count(),
        rows.iter().filter(|r| r.status == "missing").count(),
        csv_path.display()
    );
    match super::plots::write_all(&rows, &dir.join("plots")) {
        Ok(files) => {
            for f in files {
                crate::outln!("wrote {}", f.display());
            }
            exit::OK
        }
        Err(e) => {
            crate::errln!("hitl campaign collect: plots: {e}");
            exit::BAD_INPUT
        }
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
}
