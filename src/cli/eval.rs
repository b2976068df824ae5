//! `hitl eval RUN.mcap [--json] [--per-frame] [--backend B]`: pose metrics of a recording, as the paper defines
//! them (see `hitl_perception::metrics` and docs/perception.md).
//!
//! Ground truth is `/pose/gt`; the estimate is `/pose/estimate` matched by the frame's capture
//! timestamp, or, with `--backend`, a backend re-run offline over the recorded frames. `scale`
//! (lab metres per real metre) comes from the `run` metadata record unless `--scale` is given.

use crate::cli::reregister::ReregisterArgs;
use crate::exit;
use hitl_hal::Pose;
use hitl_perception::metrics::{evaluate_symmetric, frame_error, PosePair};
use hitl_perception::models::Symmetry;
use hitl_perception::replay::replay_frames;
use hitl_perception::reregister::METADATA_KEY;
use hitl_perception::BackendSpec;
use hitl_perception::{backend_from_spec, ReregisterPolicy, Reregistering, TargetModel};
use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

/// Score a recording's pose estimates against its ground truth.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// The recording (MCAP); a file cut short by a crash or damaged is read as far as it is
    /// sound, and the output says how many of its frames that was.
    pub recording: PathBuf,
    /// Print one JSON object (frames, scale, mean/median/std of e_t and e_r, failures, ...).
    #[arg(long)]
    pub json: bool,
    /// Re-run a backend offline over the recorded frames: icp, mono (the monocular baseline:
    /// colour and mask, no depth), onnx:MODEL.onnx, or socket:PATH (an external estimator
    /// listening on a unix socket, docs/perception.md).
    #[arg(long)]
    pub backend: Option<String>,
    /// Target model for --backend: a built-in name (asymmetric, one-plane, two-planes) or an
    /// .obj/.stl file (default: the run's `target_model` metadata, else asymmetric).
    #[arg(long)]
    pub target: Option<String>,
    /// The target's symmetry for the symmetry-aware figures (`*_sym_*`): none, one-plane,
    /// two-planes:AXIS, N-fold:AXIS, revolution:AXIS, joined by + (docs/perception.md). Default:
    /// the declared symmetry of the target (--target, else the run's `target_model`): a built-in's
    /// own, an OBJ/STL's `FILE.symmetry` file, else none. The paper's e_t and e_r never change.
    #[arg(long, value_name = "SPEC")]
    pub target_symmetry: Option<String>,
    /// Lab metres per real metre (default: the run's `scale` metadata).
    #[arg(long)]
    pub scale: Option<f64>,
    /// With --backend: when to re-register (default: what the recorded run used, from its
    /// metadata; else on the first frame and after a lost one only).
    #[command(flatten)]
    pub reregister: ReregisterArgs,
    /// With --backend: decimate the estimator's mesh to at most N faces (quadric decimation,
    /// meshoptimizer) before re-running it; the rendered target was never decimated. The paper's
    /// RQ2 mesh resolution.
    #[arg(long, value_name = "N")]
    pub mesh_faces: Option<usize>,
    /// Also list every frame's errors (e_t, e_r, or "failed"), to see where a track went wrong;
    /// with --json they go in a `per_frame` array.
    #[arg(long)]
    pub per_frame: bool,
}

pub fn run(args: EvalArgs) -> u8 {
    match eval(&args) {
        Ok(v) => {
            if args.json {
                crate::outln!("{v}");
            } else {
                if let Some(rows) = v.get("per_frame").and_then(|p| p.as_array()) {
                    crate::outln!(
                        "frame  t [s]     e_t [m]   e_r [deg]  raw e_r [deg]  e_r sym [deg]"
                    );
                    for (i, r) in rows.iter().enumerate() {
                        let t = r.get("t_s").and_then(|x| x.as_f64()).unwrap_or(f64::NAN);
                        let raw = r.get("raw_er_deg").and_then(|x| x.as_f64()).unwrap_or(f64::NAN);
                        let sym = r.get("er_sym_deg").and_then(|x| x.as_f64()).unwrap_or(f64::NAN);
                        match (r.get("et_m").and_then(|x| x.as_f64()), r.get("er_deg")) {
                            (Some(et), Some(er)) => crate::outln!(
                                "{i:5}  {t:8.3}  {et:8.4}  {:9.3}  {raw:13.3}  {sym:13.3}",
                                er.as_f64().unwrap_or(f64::NAN)
                            ),
                            _ => crate::outln!("{i:5}  {t:8.3}  failed"),
                        }
                    }
                }
                let g = |k: &str| v.get(k).cloned().unwrap_or(serde_json::Value::Null);
                let policy = serde_json::from_value::<ReregisterPolicy>(g("reregister"));
                if let (Some(backend), Ok(policy)) = (g("backend").as_str(), policy) {
                    crate::outln!(
                        "backend {backend}, re-registered {policy}: {} resets",
                        g("backend_resets")
                    );
                }
                let frames = hitl_record::reader::frames_text(
                    g("frames_read").as_u64().unwrap_or(0),
                    g("frames_recorded").as_u64(),
                );
                match g("read_stopped").as_str() {
                    None => crate::outln!("recording: {frames} (all of it)"),
                    Some(why) => crate::outln!("recording: {frames} (not to its end: {why})"),
                }
                crate::outln!(
                    "ground truth from: {}",
                    g("calibration").as_str().unwrap_or("nominal")
                );
                crate::outln!(
                    "frames {} (failures {}), scale {}\n\
                     e_t real m: mean {} median {} std {}\n\
                     e_r deg:    mean {} median {} std {}",
                    g("frames"),
                    g("failures"),
                    g("scale"),
                    g("mean_et_m"),
                    g("median_et_m"),
                    g("std_et_m"),
                    g("mean_er_deg"),
                    g("median_er_deg"),
                    g("std_er_deg")
                );
                crate::outln!(
                    "up to the target's symmetry ({}, from {}):\n\
                     e_t real m: mean {} median {} std {}\n\
                     e_r deg:    mean {} median {} std {}",
                    g("symmetry").as_str().unwrap_or("none"),
                    g("symmetry_source").as_str().unwrap_or("?"),
                    g("mean_et_sym_m"),
                    g("median_et_sym_m"),
                    g("std_et_sym_m"),
                    g("mean_er_sym_deg"),
                    g("median_er_sym_deg"),
                    g("std_er_sym_deg")
                );
            }
            exit::OK
        }
        Err(e) => {
            crate::errln!("hitl eval: {e}");
            exit::BAD_INPUT
        }
    }
}

fn eval(args: &EvalArgs) -> Result<serde_json::Value, String> {
    let path = &args.recording;
    if args.reregister.given() && args.backend.is_none() {
        return Err("--reregister-every and --reregister-residual-m apply to a --backend re-run; \
                    the recorded estimates are scored as they are"
            .into());
    }
    if args.mesh_faces.is_some() && args.backend.is_none() {
        return Err("--mesh-faces decimates the mesh of a --backend re-run; \
                    the recorded estimates are scored as they are"
            .into());
    }
    let rec = hitl_record::reader::read_recording(path).map_err(|e| e.to_string())?;
    let run_meta = rec.metadata.get("run");
    let scale = match args.scale {
        Some(s) => s,
        None => run_meta
            .and_then(|m| m.get("scale"))
            .ok_or_else(|| {
                format!("{}: the run metadata has no `scale`; pass --scale", path.display())
            })?
            .parse::<f64>()
            .map_err(|e| format!("{}: run metadata `scale`: {e}", path.display()))?,
    };
    if rec.pose_gt.is_empty() {
        return Err(format!("{}: no /pose/gt messages", path.display()));
    }
    let mut extra = serde_json::Map::new();
    let target_spec =
        args.target.clone().or_else(|| run_meta.and_then(|m| m.get("target_model")).cloned());
    let (symmetry, symmetry_source) = target_symmetry(
        args.target_symmetry.as_deref(),
        target_spec.as_deref(),
        args.target.is_some(),
        "hitl eval",
    )?;
    extra.insert("symmetry_source".into(), serde_json::json!(symmetry_source));
    let estimates: HashMap<u64, Pose> = match &args.backend {
        None => rec.pose_estimate.iter().map(|p| (p.capture_ns, p.pose)).collect(),
        Some(b) => rerun_backend(args, b, target_spec.as_deref(), scale, run_meta, &mut extra)?,
    };
    let pairs = pose_pairs(&rec.pose_gt, &estimates);
    let m = evaluate_symmetric(&pairs, scale, &symmetry).map_err(|e| e.to_string())?;
    let mut v = m.to_json();
    if args.per_frame {
        extra.insert("per_frame".into(), per_frame(&pairs, &m));
    }
    if let Some(obj) = v.as_object_mut() {
        obj.extend(extra);
        // The calibration the ground truth came from (recordings before it existed: nominal).
        let calibration = run_meta
            .and_then(|m| m.get(hitl_record::metadata::CALIBRATION_KEY))
            .map_or("nominal", |c| c.as_str());
        obj.insert("calibration".into(), serde_json::json!(calibration));
        // How much of the recording was read (a damaged or cut file is read as far as it is
        // sound): `complete` (also as `recording_complete`, its older name), the frames read
        // and recorded (null: unknown, the file has no summary) and why reading stopped.
        let end = rec.end.as_ref();
        let complete = end.is_some_and(|e| e.complete);
        obj.insert("recording_complete".into(), serde_json::json!(complete));
        obj.insert("complete".into(), serde_json::json!(complete));
        obj.insert("frames_read".into(), serde_json::json!(end.map_or(0, |e| e.frames_read)));
        obj.insert(
            "frames_recorded".into(),
            serde_json::json!(end.and_then(|e| e.frames_recorded)),
        );
        obj.insert("read_stopped".into(), serde_json::json!(end.and_then(|e| e.truncated.clone())));
    }
    if let Some(w) = rec.end.as_ref().and_then(|e| e.warning(path)) {
        crate::errln!("hitl eval: warning: {w}");
    }
    Ok(v)
}

/// Re-run the recording's frames through `--backend` `backend` (against `target_spec`'s mesh at
/// `scale`, re-registered by the flags' or the recorded policy); the estimates by capture time.
/// What the re-run was (backend, policy, frames, errors, speed) goes into `extra`.
fn rerun_backend(
    args: &EvalArgs,
    backend: &str,
    target_spec: Option<&str>,
    scale: f64,
    run_meta: Option<&BTreeMap<String, String>>,
    extra: &mut serde_json::Map<String, serde_json::Value>,
) -> Result<HashMap<u64, Pose>, String> {
    let path = &args.recording;
    let spec: BackendSpec = backend.parse().map_err(|e| format!("{e}"))?;
    let target = target_spec.unwrap_or("asymmetric").to_string();
    let model = TargetModel::from_spec(&target).map_err(|e| e.to_string())?;
    let mut mesh = model.lab_mesh(scale).map_err(|e| e.to_string())?;
    if let Some(n) = args.mesh_faces {
        let d = hitl_perception::models::decimate::decimate(&mesh, n)
            .map_err(|e| format!("--mesh-faces {n}: {e}"))?;
        extra.insert("mesh_faces".into(), serde_json::json!(d.mesh.faces().len()));
        extra.insert("mesh_faces_before".into(), serde_json::json!(d.faces_before));
        mesh = d.mesh;
    }
    let policy = if args.reregister.given() {
        args.reregister.policy().map_err(|e| e.to_string())?
    } else {
        recorded_policy(run_meta, path)?
    };
    let est = backend_from_spec(&spec, &mesh, &model.lab_symmetry(scale))
        .map_err(|e| e.to_string())?
        .ok_or("--backend none has nothing to run")?;
    let mut est = Reregistering::new(est, policy);
    let mut out = HashMap::new();
    let (mut errors, mut resets) = (0usize, 0u64);
    let t0 = std::time::Instant::now();
    let summary = replay_frames(path, |f| {
        let (r, n) = est.estimate(&f);
        resets += u64::from(n);
        match r {
            Ok(e) => {
                if let Some(p) = e.pose {
                    out.insert(f.timestamp_ns, p);
                }
            }
            Err(_) => errors += 1,
        }
    })
    .map_err(|e| e.to_string())?;
    let secs = t0.elapsed().as_secs_f64();
    extra.insert("backend".into(), serde_json::json!(est.name()));
    extra.insert("reregister".into(), serde_json::json!(policy));
    extra.insert("backend_resets".into(), serde_json::json!(resets));
    extra.insert("target".into(), serde_json::json!(target));
    extra.insert("replayed_frames".into(), serde_json::json!(summary.frames));
    extra.insert("backend_errors".into(), serde_json::json!(errors));
    extra.insert(
        "backend_fps".into(),
        serde_json::json!(if secs > 0.0 { summary.frames as f64 / secs } else { 0.0 }),
    );
    Ok(out)
}

/// The symmetry the `_sym` figures are taken up to, and where it came from: `flag`
/// (`--target-symmetry`), else the declaration of `target` (a built-in's own, an OBJ/STL's
/// `FILE.symmetry`), else none. A target that cannot be loaded (a recording moved to another
/// machine) leaves the symmetry undeclared with a warning, unless `strict` (the user named it):
/// the paper's figures need no model. `who` prefixes the warning.
pub(crate) fn target_symmetry(
    flag: Option<&str>,
    target: Option<&str>,
    strict: bool,
    who: &str,
) -> Result<(Symmetry, String), String> {
    if let Some(spec) = flag {
        let s = Symmetry::parse(spec).map_err(|e| format!("--target-symmetry: {e}"))?;
        return Ok((s, "--target-symmetry".into()));
    }
    let Some(target) = target else {
        return Ok((Symmetry::none(), "no target named (none declared)".into()));
    };
    match TargetModel::from_spec(target) {
        Ok(m) if hitl_perception::models::builtin(target).is_some() => {
            Ok((m.symmetry_group, format!("built-in target {target}")))
        }
        Ok(m) => {
            let side = Symmetry::sidecar_path(std::path::Path::new(target));
            let source = if side.exists() {
                side.display().to_string()
            } else {
                format!("{target} (no {} file: none declared)", side.display())
            };
            Ok((m.symmetry_group, source))
        }
        Err(e) if strict => Err(format!("--target: {e}")),
        Err(e) => {
            crate::errln!(
                "{who}: warning: the run's target {target} cannot be loaded ({e}); the \
                 symmetry-aware figures assume no symmetry (--target-symmetry declares one)"
            );
            Ok((Symmetry::none(), format!("{target} unreadable (none declared)")))
        }
    }
}

/// Ground truth paired with the estimates of the same capture, in capture order.
pub(crate) fn pose_pairs(
    gt: &[hitl_record::PoseStamped],
    estimates: &HashMap<u64, Pose>,
) -> Vec<PosePair> {
    gt.iter()
        .map(|g| PosePair {
            timestamp_ns: g.capture_ns,
            gt: g.pose,
            est: estimates.get(&g.capture_ns).copied(),
        })
        .collect()
}

/// The re-registration policy the recorded run used (none recorded: the default).
fn recorded_policy(
    run_meta: Option<&std::collections::BTreeMap<String, String>>,
    path: &std::path::Path,
) -> Result<ReregisterPolicy, String> {
    match run_meta.and_then(|m| m.get(METADATA_KEY)) {
        None => Ok(ReregisterPolicy::default()),
        Some(json) => {
            let bad = |e: &dyn std::fmt::Display| {
                format!("{}: run metadata `{METADATA_KEY}`: {e}", path.display())
            };
            let p: ReregisterPolicy = serde_json::from_str(json).map_err(|e| bad(&e))?;
            ReregisterPolicy::new(p.every_n_frames, p.max_residual_m).map_err(|e| bad(&e))
        }
    }
}

/// One row per ground-truth frame, in capture order: its time from the first frame and its
/// errors, or only the time when the frame was not scored (no estimate, or an invalid one).
/// `raw_er_deg` is the rotation error before the first-frame calibration: a calibration frame
/// that was itself off shows there as a constant offset.
fn per_frame(pairs: &[PosePair], m: &hitl_perception::metrics::Metrics) -> serde_json::Value {
    let t0 = pairs.first().map_or(0, |p| p.timestamp_ns);
    let scored: HashMap<u64, &hitl_perception::FrameError> =
        m.per_frame.iter().map(|f| (f.timestamp_ns, f)).collect();
    pairs
        .iter()
        .map(|p| {
            let t_s = p.timestamp_ns.saturating_sub(t0) as f64 / 1e9;
            match scored.get(&p.timestamp_ns) {
                Some(f) => serde_json::json!({
                    "timestamp_ns": p.timestamp_ns, "t_s": t_s, "et_m": f.et_m, "er_deg": f.er_deg,
                    "et_sym_m": f.et_sym_m, "er_sym_deg": f.er_sym_deg,
                    "raw_er_deg": p.est.map(|e| frame_error(&e, &p.gt, 1.0).1),
                }),
                None => serde_json::json!({ "timestamp_ns": p.timestamp_ns, "t_s": t_s }),
            }
        })
        .collect()
}
