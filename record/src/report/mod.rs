//! `hitl report`: a summary JSON, SVG plots and an `index.html` for one recording.

pub mod plots;
pub mod summary;

use crate::reader::{read_recording, Recording};
use std::path::{Path, PathBuf};

pub use summary::{summarize, Summary};

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error(transparent)]
    Read(#[from] crate::ReadError),
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("plot {name}: {reason}")]
    Plot { name: String, reason: String },
}

/// What was written.
#[derive(Debug, Clone)]
pub struct ReportOutput {
    pub dir: PathBuf,
    pub summary: Summary,
    /// Every file written (summary.json, plots, index.html).
    pub files: Vec<PathBuf>,
}

/// The default output folder: `RUN_report/` next to `RUN.mcap`.
pub fn default_out_dir(mcap: &Path) -> PathBuf {
    let stem =
        mcap.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "run".into());
    mcap.with_file_name(format!("{stem}_report"))
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ReportError + '_ {
    move |e| ReportError::Io { path: path.display().to_string(), source: e }
}

type PlotFn = fn(&Recording, &Path) -> Result<(), String>;

/// Read `mcap` and write the report into `out_dir` (default: [`default_out_dir`]).
pub fn write_report(mcap: &Path, out_dir: Option<&Path>) -> Result<ReportOutput, ReportError> {
    let rec = read_recording(mcap)?;
    let dir = out_dir.map(Path::to_path_buf).unwrap_or_else(|| default_out_dir(mcap));
    std::fs::create_dir_all(&dir).map_err(io(&dir))?;
    let summary = summarize(&rec);
    let mut files = Vec::new();
    let sj = dir.join("summary.json");
    let text = serde_json::to_string_pretty(&summary)
        .map_err(|e| ReportError::Io { path: sj.display().to_string(), source: e.into() })?;
    std::fs::write(&sj, text).map_err(io(&sj))?;
    files.push(sj);

    let mut plots: Vec<(&str, &str, PlotFn)> = vec![
        ("joints.svg", "Setpoint vs measured joints", plots::joints),
        ("tracking_error.svg", "Tracking error", plots::tracking_error),
        ("lateness.svg", "Loop lateness", plots::lateness_histogram),
    ];
    if !rec.tf.is_empty() {
        plots.push(("camera_path.svg", "Camera path around the target", plots::camera_path));
    }
    if rec.sun_phase().is_some() || !rec.lights.is_empty() {
        plots.push(("sun_phase.svg", "Sun phase and light", plots::sun_phase));
    }
    if !rec.pose_estimate.is_empty() {
        plots.push(("pose_error.svg", "Pose error", plots::pose_error));
    }
    let mut shown = Vec::new();
    for (name, title, f) in plots {
        let p = dir.join(name);
        f(&rec, &p).map_err(|reason| ReportError::Plot { name: name.to_string(), reason })?;
        files.push(p);
        shown.push((name, title));
    }
    let html = dir.join("index.html");
    std::fs::write(&html, index_html(mcap, &summary, &shown)).map_err(io(&html))?;
    files.push(html);
    Ok(ReportOutput { dir, summary, files })
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

fn index_html(mcap: &Path, s: &Summary, plots: &[(&str, &str)]) -> String {
    let mut h = String::new();
    let name = esc(&mcap.display().to_string());
    h.push_str(&format!(
        "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>hitl report: {name}</title>\n<style>body{{font-family:sans-serif;margin:2em;max-width:1150px}}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:left}}.bad{{color:#b00}}img{{max-width:100%;border:1px solid #eee;margin:8px 0}}</style></head><body>\n<h1>hitl run report</h1>\n<p>{name}</p>\n"
    ));
    let state = if s.complete {
        "closed cleanly".to_string()
    } else {
        format!(
            "<span class=\"bad\">cut short: {}</span>",
            esc(s.truncated.as_deref().unwrap_or("no footer"))
        )
    };
    h.push_str(&format!(
        "<table><tr><th>file</th><td>{state}</td></tr><tr><th>duration</th><td>{:.2} s</td></tr>",
        s.duration_s
    ));
    if let Some(t) = &s.tracking {
        h.push_str(&format!(
            "<tr><th>max tracking error</th><td>{:.3} deg</td></tr>",
            t.max_abs_deg
        ));
    }
    if let Some(l) = &s.timing.wake_late_us {
        h.push_str(&format!(
            "<tr><th>tick lateness</th><td>p50 {:.1} us, p99 {:.1} us, max {:.1} us; {} overruns in {} ticks</td></tr>",
            l.p50, l.p99, l.max, s.timing.overruns, s.timing.ticks
        ));
    }
    if let Some(c) = &s.capture_sync_ms {
        h.push_str(&format!(
            "<tr><th>capture sync error</th><td>{} frames: mean {:.2} ms, p99 {:.2} ms, max {:.2} ms (exposure minus trigger)</td></tr>",
            c.count, c.mean, c.p99, c.max
        ));
    }
    if let Some(p) = &s.pose_error {
        if let (Some(t), Some(r)) = (&p.translation_mm, &p.rotation_deg) {
            h.push_str(&format!(
                "<tr><th>pose error</th><td>{} pairs: translation mean {:.1} mm (max {:.1}), rotation mean {:.2} deg (max {:.2})</td></tr>",
                p.pairs, t.mean, t.max, r.mean, r.max
            ));
        }
    }
    let drops: u64 = s.dropped.values().sum();
    h.push_str(&format!(
        "<tr><th>telemetry dropped</th><td{}>{drops}</td></tr><tr><th>captures not recorded</th><td{}>{}</td></tr></table>\n",
        if drops > 0 { " class=\"bad\"" } else { "" },
        if s.frames_not_recorded > 0 { " class=\"bad\"" } else { "" },
        s.frames_not_recorded
    ));
    h.push_str("<h2>Safety events</h2>\n");
    if s.events.is_empty() {
        h.push_str("<p>none</p>\n");
    } else {
        h.push_str("<table><tr><th>t (s)</th><th>kind</th><th>detail</th></tr>");
        for e in &s.events {
            h.push_str(&format!(
                "<tr><td>{:.3}</td><td>{}</td><td>{}</td></tr>",
                e.t_s,
                esc(&e.kind),
                esc(&e.detail)
            ));
        }
        h.push_str("</table>\n");
    }
    for (file, title) in plots {
        h.push_str(&format!(
            "<h2>{}</h2>\n<img src=\"{}\" alt=\"{}\">\n",
            esc(title),
            esc(file),
            esc(title)
        ));
    }
    h.push_str("<h2>Topics</h2>\n<table><tr><th>topic</th><th>messages</th></tr>");
    for (t, n) in &s.topic_counts {
        h.push_str(&format!("<tr><td>{}</td><td>{n}</td></tr>", esc(t)));
    }
    h.push_str("</table>\n<p><a href=\"summary.json\">summary.json</a></p>\n</body></html>\n");
    h
}
