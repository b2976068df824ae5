//! `hitl report RUN.mcap [--out DIR]`: summary JSON, plots, a contact sheet and an index.html
//! for one run. This is where the report meets the perception crate: the contact sheet's target
//! model is the run's (`target_model` and `scale` of its metadata, scaled as the run scaled it).

use crate::exit;
use hitl_record::report::{
    default_out_dir, write_report_with, ContactOptions, ReportError, ReportOptions, TargetMesh,
};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Write a report of a recording: summary.json, SVG plots, a contact sheet (a few captures with
/// the target's ground-truth and estimated silhouettes outlined) and index.html.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The recording (MCAP) to report on; a file cut short by a crash or damaged is read as far
    /// as it is sound, and the report says how many of its frames that was.
    pub recording: PathBuf,
    /// Output folder (default: RUN_report/ next to RUN.mcap).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Captures on the contact sheet (evenly spread over the run; 0: no sheet).
    #[arg(long, default_value_t = 8)]
    pub contact_frames: usize,
    /// Contact sheet frames wider than this are shrunk to it (pixels, at least 16).
    #[arg(long, default_value_t = 480, value_parser = clap::value_parser!(u32).range(16..))]
    pub contact_width: u32,
    /// Show each contact-sheet frame cropped around the target: its ground-truth mask's box grown
    /// Z times (at least 1), at the frame's aspect ratio, drawn the sheet's full width (so the
    /// target spans about 1/Z of it; 1.5 lets it fill most of the tile). Without it, whole frames
    /// (at a fly-around's range a wide camera shows the target a few dozen pixels wide).
    #[arg(long, value_name = "Z")]
    pub contact_zoom: Option<f64>,
    /// The target's symmetry for the report's symmetry-aware pose metrics, as `hitl eval
    /// --target-symmetry` (default: the run's target's declaration).
    #[arg(long, value_name = "SPEC")]
    pub target_symmetry: Option<String>,
}

/// The paper's pose metrics of a recording and the same up to the target's symmetry, as `hitl
/// eval --json` gives them (the report's `pose_metrics`).
fn pose_metrics(
    rec: &hitl_record::reader::Recording,
    flag: Option<&str>,
) -> Result<serde_json::Value, String> {
    let run = rec.metadata.get("run");
    let scale = run
        .and_then(|m| m.get("scale"))
        .ok_or("the run metadata has no `scale`")?
        .parse::<f64>()
        .map_err(|e| format!("run metadata `scale`: {e}"))?;
    let target = run.and_then(|m| m.get("target_model")).map(String::as_str);
    let (symmetry, source) = super::eval::target_symmetry(flag, target, false, "hitl report")?;
    let estimates = rec.pose_estimate.iter().map(|p| (p.capture_ns, p.pose)).collect();
    let pairs = super::eval::pose_pairs(&rec.pose_gt, &estimates);
    let m = hitl_perception::metrics::evaluate_symmetric(&pairs, scale, &symmetry)
        .map_err(|e| e.to_string())?;
    let mut v = m.to_json();
    if let Some(o) = v.as_object_mut() {
        o.insert("symmetry_source".into(), serde_json::json!(source));
        // Per frame, for the report's plot of the paper's error over the run.
        let rows: Vec<serde_json::Value> = m
            .per_frame
            .iter()
            .map(|f| {
                serde_json::json!({
                    "t_ns": f.timestamp_ns,
                    "et_m": f.et_m,
                    "er_deg": f.er_deg,
                    "et_sym_m": f.et_sym_m,
                    "er_sym_deg": f.er_sym_deg,
                })
            })
            .collect();
        o.insert("per_frame".into(), serde_json::Value::Array(rows));
    }
    Ok(v)
}

/// The run's target model in lab metres, as `hitl run` and `hitl eval` build it: the `target_model`
/// of the run metadata (default asymmetric) scaled by its `scale`.
fn run_target(run: &BTreeMap<String, String>) -> Result<TargetMesh, String> {
    let spec = run.get("target_model").map_or("asymmetric", String::as_str);
    let scale = run
        .get("scale")
        .ok_or("the run metadata has no `scale`")?
        .parse::<f64>()
        .map_err(|e| format!("run metadata `scale`: {e}"))?;
    let model =
        hitl_perception::TargetModel::from_spec(spec).map_err(|e| format!("{spec}: {e}"))?;
    let mesh = model.lab_mesh(scale).map_err(|e| format!("{spec}: {e}"))?;
    Ok(TargetMesh { vertices: mesh.vertices().to_vec(), faces: mesh.faces().to_vec() })
}

pub fn run(args: ReportArgs) -> u8 {
    let dir = args.out.clone().unwrap_or_else(|| default_out_dir(&args.recording));
    if let Some(z) = args.contact_zoom.filter(|z| !(z.is_finite() && *z >= 1.0)) {
        crate::errln!("hitl report: --contact-zoom {z} must be a number of at least 1");
        return exit::BAD_INPUT;
    }
    if let Some(spec) = &args.target_symmetry {
        if let Err(e) = hitl_perception::models::Symmetry::parse(spec) {
            crate::errln!("hitl report: --target-symmetry: {e}");
            return exit::BAD_INPUT;
        }
    }
    let flag = args.target_symmetry.clone();
    let score = move |rec: &hitl_record::reader::Recording| pose_metrics(rec, flag.as_deref());
    let opts = ReportOptions {
        pose_metrics: Some(&score),
        contact: ContactOptions {
            frames: args.contact_frames,
            max_width: args.contact_width,
            model: Some(&run_target),
            zoom: args.contact_zoom,
        },
    };
    match write_report_with(&args.recording, Some(&dir), &opts) {
        Ok(r) => {
            if let Some(w) = nominal_hitl_warning(&args.recording) {
                crate::errln!("hitl report: warning: {w}");
            }
            if !r.summary.complete {
                let frames = hitl_record::reader::frames_text(
                    r.summary.frames_read,
                    r.summary.frames_recorded,
                );
                crate::errln!(
                    "hitl report: warning: {} was not read to its end: {}; {frames}, the report \
                     shows only those",
                    args.recording.display(),
                    r.summary.truncated.as_deref().unwrap_or("no footer")
                );
            }
            if args.json {
                match serde_json::to_string(&r.summary) {
                    Ok(s) => crate::outln!("{s}"),
                    Err(e) => {
                        crate::errln!("hitl report: {e}");
                        return exit::BAD_INPUT;
                    }
                }
            } else {
                crate::outln!("{}", r.dir.join("index.html").display());
            }
            exit::OK
        }
        Err(e @ ReportError::Read(_)) => {
            crate::errln!("hitl report: {e}");
            exit::BAD_INPUT
        }
        Err(e) => {
            crate::errln!("hitl report: {e}");
            exit::BAD_INPUT
        }
    }
}

/// A HITL (real-arm) run whose ground truth used the nominal camera mount and target pose: its
/// pose errors include the mount's and the tripod's placement errors (docs/calibration.md).
fn nominal_hitl_warning(path: &std::path::Path) -> Option<String> {
    let mut run = None;
    hitl_record::reader::visit(
        path,
        |_| std::ops::ControlFlow::Continue(()),
        |name, map| {
            if name == hitl_record::topics::META_RUN {
                run = Some(map.clone());
            }
        },
    )
    .ok()?;
    let run = run?;
    let config: serde_json::Value = serde_json::from_str(run.get("config")?).ok()?;
    let arm = config.get("arm")?.as_str()?;
    let calibration =
        run.get(hitl_record::metadata::CALIBRATION_KEY).map_or("nominal", |c| c.as_str());
    (!arm.starts_with("stub") && calibration == "nominal").then(|| {
        format!(
            "this HITL run (arm {arm}) took its ground truth from the nominal camera mount and \
             target pose: run hitl calibrate and record with the calibrated configuration for \
             quantitative errors"
        )
    })
}
