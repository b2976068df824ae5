//! `hitl report`: a summary JSON, SVG plots, a contact sheet and an `index.html` for one
//! recording.

pub mod closed_loop;
pub mod contact;
pub mod plots;
pub mod summary;

use crate::reader::{read_recording, Recording};
use std::path::{Path, PathBuf};

pub use contact::{ContactOptions, ContactSheet, ModelSource, TargetMesh};
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
    /// Every file written (summary.json, plots, the contact sheet's PNGs, index.html).
    pub files: Vec<PathBuf>,
}

/// What goes into a report beyond what the recording says by itself.
#[derive(Clone, Copy, Default)]
pub struct ReportOptions<'a> {
    pub contact: ContactOptions<'a>,
    /// The paper's calibrated pose metrics of the recording, and the same up to the target's
    /// symmetry, as one JSON object (`hitl eval --json`'s keys): the report shows them beside its
    /// own uncalibrated pose error. The caller scores (the perception crate); `None`: not shown.
    pub pose_metrics: Option<&'a PoseMetricsFn>,
}

/// Scores a recording's estimates (see [`ReportOptions::pose_metrics`]); `Err` says why not.
pub type PoseMetricsFn = dyn Fn(&Recording) -> Result<serde_json::Value, String>;

/// The default output folder: `RUN_report/` next to `RUN.mcap`.
pub fn default_out_dir(mcap: &Path) -> PathBuf {
    let stem =
        mcap.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "run".into());
    mcap.with_file_name(format!("{stem}_report"))
}

pub(crate) fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ReportError + '_ {
    move |e| ReportError::Io { path: path.display().to_string(), source: e }
}

type PlotFn = fn(&Recording, &Path) -> Result<(), String>;

/// Every plot a report may write (which ones depends on what the run recorded).
const PLOT_FILES: [&str; 8] = [
    "joints.svg",
    "tracking_error.svg",
    "lateness.svg",
    "camera_path.svg",
    "sun_phase.svg",
    "pose_error.svg",
    "paper_error.svg",
    "closed_loop_error.svg",
];

/// The list of files a report wrote, one path (relative to its folder) a line: the next report
/// into the folder removes them first, so nothing of an older report survives.
pub const MANIFEST: &str = ".hitl-report";

/// A file a report writes: a plot, `summary.json`, `index.html` or `contact/NNN.png`.
fn is_report_file(rel: &str) -> bool {
    let contact_png = rel
        .strip_prefix("contact/")
        .and_then(|n| n.strip_suffix(".png"))
        .is_some_and(|stem| !stem.is_empty() && stem.bytes().all(|b| b.is_ascii_digit()));
    contact_png || PLOT_FILES.contains(&rel) || rel == "summary.json" || rel == "index.html"
}

/// Remove what an earlier report wrote into `dir`, and only that: the files its manifest lists
/// (each checked to be a name a report writes), or, for a report written before manifests (its
/// `index.html` is a hitl report's), the plots, `summary.json` and `index.html`. Other files in
/// the folder are left alone.
fn clear_previous(dir: &Path) -> Result<(), ReportError> {
    let manifest = dir.join(MANIFEST);
    let listed: Vec<String> = match std::fs::read_to_string(&manifest) {
        Ok(text) => text.lines().map(str::to_string).collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let index = std::fs::read_to_string(dir.join("index.html")).unwrap_or_default();
            if !index.contains("<title>hitl report:") {
                return Ok(());
            }
            PLOT_FILES
                .iter()
                .chain(&["summary.json", "index.html"])
                .map(|s| s.to_string())
                .collect()
        }
        Err(e) => return Err(io(&manifest)(e)),
    };
    for rel in listed.iter().filter(|r| is_report_file(r)) {
        let path = dir.join(rel);
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io(&path)(e)),
        }
    }
    match std::fs::remove_file(&manifest) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(io(&manifest)(e)),
        _ => Ok(()),
    }
}

/// The paper's metrics and the symmetry-aware ones, as table rows.
fn pose_metrics_html(h: &mut String, m: &serde_json::Value) {
    let g = |k: &str| m.get(k).and_then(serde_json::Value::as_f64);
    let f = |x: Option<f64>, d: usize| x.map_or("-".to_string(), |x| format!("{x:.d$}"));
    if let Some(e) = m.get("error").and_then(serde_json::Value::as_str) {
        h.push_str(&format!(
            "<tr><th>paper's pose metrics</th><td>not scored: {}</td></tr>",
            esc(e)
        ));
        return;
    }
    h.push_str(&format!(
        "<tr><th>paper's pose metrics</th><td>{} frames, {} failures: e_t mean {} m (median {}) in real metres, e_r mean {}&deg; (median {}) after the first-frame calibration</td></tr>",
        m.get("frames").unwrap_or(&serde_json::Value::Null),
        m.get("failures").unwrap_or(&serde_json::Value::Null),
        f(g("mean_et_m"), 4),
        f(g("median_et_m"), 4),
        f(g("mean_er_deg"), 2),
        f(g("median_er_deg"), 2),
    ));
    h.push_str(&format!(
        "<tr><th>up to symmetry ({})</th><td>e_t mean {} m (median {}), e_r mean {}&deg; (median {}): each frame against the nearest of the target's indistinguishable poses</td></tr>",
        esc(m.get("symmetry").and_then(serde_json::Value::as_str).unwrap_or("none")),
        f(g("mean_et_sym_m"), 4),
        f(g("median_et_sym_m"), 4),
        f(g("mean_er_sym_deg"), 2),
        f(g("median_er_sym_deg"), 2),
    ));
}

/// Read `mcap` and write the report into `out_dir` (default: [`default_out_dir`]); the contact
/// sheet has no target model, so it shows the recorded masks only.
pub fn write_report(mcap: &Path, out_dir: Option<&Path>) -> Result<ReportOutput, ReportError> {
    write_report_with(mcap, out_dir, &ReportOptions::default())
}

/// [`write_report`] with options (the target model for the contact sheet's silhouettes).
pub fn write_report_with(
    mcap: &Path,
    out_dir: Option<&Path>,
    opts: &ReportOptions<'_>,
) -> Result<ReportOutput, ReportError> {
    let rec = read_recording(mcap)?;
    let dir = out_dir.map(Path::to_path_buf).unwrap_or_else(|| default_out_dir(mcap));
    std::fs::create_dir_all(&dir).map_err(io(&dir))?;
    clear_previous(&dir)?;
    let mut summary = summarize(&rec);
    let mut files = Vec::new();
    if opts.contact.frames > 0 {
        let (sheet, pngs) = contact::write_contact_sheet(mcap, &rec, &dir, &opts.contact)?;
        summary.contact_sheet = Some(sheet);
        files.extend(pngs);
    }
    if let Some(score) = opts.pose_metrics.filter(|_| !rec.pose_estimate.is_empty()) {
        summary.pose_metrics = Some(match score(&rec) {
            Ok(v) => v,
            Err(e) => serde_json::json!({ "error": e }),
        });
    }
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
    if summary.closed_loop_error.is_some() {
        plots.push((
            "closed_loop_error.svg",
            "Relative-position error, open and closed loop",
            plots::closed_loop_error,
        ));
    }
    let mut shown = Vec::new();
    let per_frame = summary
        .pose_metrics
        .as_ref()
        .and_then(|m| m.get("per_frame"))
        .and_then(serde_json::Value::as_array)
        .filter(|v| !v.is_empty());
    if let Some(rows) = per_frame {
        let (name, p) = ("paper_error.svg", dir.join("paper_error.svg"));
        plots::paper_error(&rec, rows, &p)
            .map_err(|reason| ReportError::Plot { name: name.to_string(), reason })?;
        files.push(p);
        shown.push((name, "The paper's pose error per frame, and up to symmetry"));
    }
    for (name, title, f) in plots {
        let p = dir.join(name);
        f(&rec, &p).map_err(|reason| ReportError::Plot { name: name.to_string(), reason })?;
        files.push(p);
        shown.push((name, title));
    }
    let html = dir.join("index.html");
    std::fs::write(&html, index_html(mcap, &summary, &shown)).map_err(io(&html))?;
    files.push(html);
    let listed: Vec<String> = files
        .iter()
        .filter_map(|f| f.strip_prefix(&dir).ok())
        .map(|r| r.to_string_lossy().replace('\\', "/"))
        .collect();
    let manifest = dir.join(MANIFEST);
    std::fs::write(&manifest, listed.join("\n") + "\n").map_err(io(&manifest))?;
    Ok(ReportOutput { dir, summary, files })
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

fn index_html(mcap: &Path, s: &Summary, plots: &[(&str, &str)]) -> String {
    let mut h = String::new();
    let name = esc(&mcap.display().to_string());
    h.push_str(&format!(
        "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>hitl report: {name}</title>\n<style>body{{font-family:sans-serif;margin:2em;max-width:1150px}}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:left}}.bad{{color:#b00}}img{{max-width:100%;border:1px solid #eee;margin:8px 0}}.sheet{{display:grid;grid-template-columns:repeat(auto-fill,minmax(360px,1fr));gap:10px}}.sheet figure{{margin:0}}.sheet img{{width:100%;height:auto;image-rendering:pixelated;margin:0}}.sheet figcaption{{font-size:90%}}.sw{{display:inline-block;width:1.6em;height:0.35em;vertical-align:middle;margin:0 0.4em 0 1em}}</style></head><body>\n<h1>hitl run report</h1>\n<p>{name}</p>\n"
    ));
    let frames = crate::reader::frames_text(s.frames_read, s.frames_recorded);
    let state = if s.complete {
        format!("read whole; {frames}")
    } else {
        format!(
            "<span class=\"bad\">not read to its end: {}; {frames}</span>",
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
    if let Some(m) = &s.pose_metrics {
        pose_metrics_html(&mut h, m);
    }
    if let Some(p) = &s.pose_error {
        if let (Some(t), Some(r)) = (&p.translation_mm, &p.rotation_deg) {
            let scale = s.scale.as_deref().and_then(|x| x.parse::<f64>().ok()).filter(|x| *x > 0.0);
            let real = scale.map_or(String::new(), |k| {
                format!(
                    "translation mean {:.3} m (max {:.3}) in real metres, ",
                    t.mean / 1e3 / k,
                    t.max / 1e3 / k
                )
            });
            h.push_str(&format!(
                "<tr><th>pose error as recorded</th><td>{} pairs, no first-frame calibration: {real}{:.1} mm (max {:.1}) in the lab; rotation mean {:.2}&deg; (max {:.2})</td></tr>",
                p.pairs, t.mean, t.max, r.mean, r.max
            ));
        }
    }
    if let Some(c) = &s.closed_loop_error {
        closed_loop_html(&mut h, c);
    }
    let drops: u64 = s.dropped.values().sum();
    h.push_str(&format!(
        "<tr><th>telemetry dropped</th><td{}>{drops}</td></tr><tr><th>captures not recorded</th><td{}>{}</td></tr></table>\n",
        if drops > 0 { " class=\"bad\"" } else { "" },
        if s.frames_not_recorded > 0 { " class=\"bad\"" } else { "" },
        s.frames_not_recorded
    ));
    if let Some(sheet) = &s.contact_sheet {
        contact_html(&mut h, sheet);
    }
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

/// The closed loop's row: the relative-position error open and closed, mean and at the end.
fn closed_loop_html(h: &mut String, c: &closed_loop::ClosedLoopError) {
    let mean = |s: &Option<summary::Spread>| s.as_ref().map_or(f64::NAN, |s| s.mean);
    let (open_end, closed_end) = c.last.map_or((f64::NAN, f64::NAN), |l| (l.open_mm, l.closed_mm));
    h.push_str(&format!(
        "<tr><th>relative-position error (closed loop)</th><td>{} captures, as vision measured it: open loop mean {:.3} mm (last {:.3}), closed loop mean {:.3} mm (last {:.3}), lab</td></tr>",
        c.per_capture.len(),
        mean(&c.open_mm),
        open_end,
        mean(&c.closed_mm),
        closed_end
    ));
}

fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// The contact sheet's section: legend, one captioned figure per capture, and its notes.
fn contact_html(h: &mut String, sheet: &ContactSheet) {
    use contact::{GroundTruthSource, ESTIMATE_COLOUR, GROUND_TRUTH_COLOUR};
    h.push_str("<h2>Contact sheet</h2>\n");
    if !sheet.frames.is_empty() {
        h.push_str(&format!(
            "<p>{} of {} captures, evenly spread. Outlines: <span class=\"sw\" style=\"background:{}\"></span>ground truth (the recorded mask; the target model at the ground-truth pose where no mask was recorded) <span class=\"sw\" style=\"background:{}\"></span>estimate (the target model at the estimated pose; drawn over the ground truth where they meet). e_t is the estimate's translation error in real metres (lab millimetres without a recorded scale), e_r its rotation error as recorded; <code>hitl eval</code> gives the paper's calibrated figures.</p>\n<div class=\"sheet\">\n",
            sheet.frames.len(),
            sheet.captures,
            hex(GROUND_TRUTH_COLOUR),
            hex(ESTIMATE_COLOUR)
        ));
        for f in &sheet.frames {
            let mut cap = format!("capture {} &middot; t {:.2} s", f.capture, f.t_s);
            match (f.et_m, f.et_lab_mm, f.er_deg) {
                (Some(et), _, Some(er)) => {
                    cap.push_str(&format!(" &middot; e_t {et:.3} m &middot; e_r {er:.2}&deg;"))
                }
                (None, Some(mm), Some(er)) => cap
                    .push_str(&format!(" &middot; e_t {mm:.1} mm (lab) &middot; e_r {er:.2}&deg;")),
                _ => cap.push_str(" &middot; no estimate"),
            }
            match f.ground_truth {
                Some(GroundTruthSource::Mask) => {}
                Some(GroundTruthSource::Model) => {
                    cap.push_str(" &middot; ground truth from the model")
                }
                None => cap.push_str(" &middot; no ground truth"),
            }
            if f.et_lab_mm.is_some() && !f.estimate {
                cap.push_str(" (no model to draw it)");
            }
            h.push_str(&format!(
                "<figure><img src=\"{}\" alt=\"capture {}\" width=\"{}\" height=\"{}\"><figcaption>{cap}</figcaption></figure>\n",
                esc(&f.file),
                f.capture,
                f.width,
                f.height
            ));
        }
        h.push_str("</div>\n");
    }
    for n in &sheet.notes {
        h.push_str(&format!("<p>{}</p>\n", esc(n)));
    }
}
