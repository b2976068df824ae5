//! `hitl campaign run`: play a manifest's cases on this machine, N at a time. Each case is three
//! child processes of this same executable (`hitl plan`, a SITL `hitl run` with a recording,
//! `hitl eval --json`), so a case that fails, or crashes, is recorded and the campaign goes on.
//! Each stage's output is renamed into place only when the stage is over, so an interrupted
//! campaign resumes where it stopped; a case whose result exists for the same definition is
//! skipped. Campaigns drive the embedded stub only (no `--arm` is ever passed).

use super::manifest::{Case, Manifest};
use super::phase;
use super::store::{self, write_atomic};
use hitl_trajectories::planner::DEFAULT_WAYPOINT_RATE_HZ;
use serde_json::{json, Value};
use std::io::{self, BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// Exit code of a campaign in which at least one case failed (each case's own exit code is in its
/// result).
pub const CASES_FAILED: u8 = 1;

/// Characters of a failed stage's output kept in its result.
const TAIL_CHARS: usize = 2000;

/// How to run a campaign.
#[derive(Debug, Clone)]
pub struct RunOptions {
    pub out: PathBuf,
    pub jobs: usize,
    pub index: Option<usize>,
    pub plain: bool,
    /// The `hitl` executable the stages run.
    pub exe: PathBuf,
}

/// Cases at a time when `--jobs` is not given: half the cores (at least one), so every run's
/// real-time loop, renderer and estimator keep a core's worth of room.
pub fn default_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, |n| (n.get() / 2).max(1))
}

/// What one case came to.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Skipped,
    Ok,
    Failed { stage: String, code: Option<i32> },
}

/// Exit code of a `campaign run` refused because another one holds the folder (or, with
/// `--index`, the case): sysexits' EX_TEMPFAIL, "try again later".
pub const FOLDER_BUSY: u8 = 75;

/// Set by Ctrl-C: no new case or stage starts.
static STOP: AtomicBool = AtomicBool::new(false);

/// Play the cases; returns the exit code (0 all done, [`CASES_FAILED`], 130 interrupted, 2 bad
/// `--index` or output folder, [`FOLDER_BUSY`]).
pub fn run(manifest: &Manifest, manifest_text: &str, opts: &RunOptions) -> u8 {
    let n = manifest.len();
    let selected: Vec<usize> = match opts.index {
        Some(i) if i < n => vec![i],
        Some(i) => {
            crate::errln!(
                "hitl campaign run: --index {i} is out of range: {} has {n} cases (0-{})",
                manifest.path.display(),
                n.saturating_sub(1)
            );
            return crate::exit::BAD_INPUT;
        }
        None => (0..n).collect(),
    };
    if let Err(e) = std::fs::create_dir_all(opts.out.join("cases")) {
        crate::errln!("hitl campaign run: {}: {e}", opts.out.display());
        return crate::exit::BAD_INPUT;
    }
    // A whole campaign holds its folder alone; array tasks (--index) share it with each other
    // and each holds its case below.
    let lock_path = store::folder_lock_path(&opts.out);
    let _folder_lock = match store::try_lock(&lock_path, opts.index.is_none()) {
        Ok(f) => f,
        Err(store::LockError::Busy) => {
            crate::errln!(
                "hitl campaign run: {} is in use: another `hitl campaign run` is playing it (it \
                 holds {}); nothing was changed. Wait for it to end, or give another --out",
                opts.out.display(),
                lock_path.display()
            );
            return FOLDER_BUSY;
        }
        Err(store::LockError::Io(e)) => {
            crate::errln!("hitl campaign run: {}: {e}", lock_path.display());
            return crate::exit::BAD_INPUT;
        }
    };
    if let Err(e) = write_index(manifest, manifest_text, &opts.out, opts.index.is_some()) {
        crate::errln!("hitl campaign run: {}: {e}", opts.out.display());
        return crate::exit::BAD_INPUT;
    }
    // An array task holds its case: a second task with the same index is refused, not played
    // twice into one folder.
    let _case_lock = match (opts.index, opts.index.and_then(|i| manifest.case(i))) {
        (Some(i), Some(case)) => match lock_case(&opts.out, &case) {
            Ok(f) => Some(f),
            Err(store::LockError::Busy) => {
                crate::errln!(
                    "hitl campaign run: case {i} [{}] is being played by another `hitl campaign \
                     run --index {i}` on {}; nothing was changed",
                    case.id,
                    opts.out.display()
                );
                return FOLDER_BUSY;
            }
            Err(store::LockError::Io(e)) => {
                crate::errln!("hitl campaign run: {}: {e}", opts.out.display());
                return crate::exit::BAD_INPUT;
            }
        },
        _ => None,
    };
    let (done, todo) = cases_to_play(manifest, selected, &opts.out);
    crate::outln!(
        "campaign {}: {} cases, {} already done, {} to run, {} at a time -> {}",
        manifest.name,
        done + todo.len(),
        done,
        todo.len(),
        opts.jobs.min(todo.len()).max(1),
        opts.out.display()
    );
    // Ctrl-C: no new case or stage starts, and the running stages get it too (they are in
    // process groups of their own, which a terminal's Ctrl-C does not reach): `hitl run` makes
    // its controlled stop. A second handler cannot be installed (tests calling this twice):
    // then Ctrl-C ends the process, and its children follow (see [`super::child`]).
    let _ = ctrlc::set_handler(|| {
        STOP.store(true, Ordering::SeqCst);
        super::child::interrupt_all();
    });
    let t0 = Instant::now();
    let outcomes = play_cases(manifest, &todo, opts);
    let failed = outcomes.iter().filter(|(_, o)| matches!(o, Outcome::Failed { .. })).count();
    let played = outcomes.len();
    crate::outln!(
        "campaign {}: {} played ({} failed), {} skipped, {} not started, in {:.1} s; \
         `hitl campaign collect {}` tabulates",
        manifest.name,
        played,
        failed,
        done,
        todo.len() - played,
        t0.elapsed().as_secs_f64(),
        opts.out.display()
    );
    if STOP.load(Ordering::SeqCst) {
        crate::errln!("hitl campaign run: interrupted; run it again to resume");
        130
    } else if failed > 0 {
        CASES_FAILED
    } else {
        crate::exit::OK
    }
}

/// Of the `selected` cases, how many are already done in `out` and which are still to play.
/// Cases by index, built when played; the same case twice (two [[matrix]] tables may both hold
/// it) is played once.
fn cases_to_play(manifest: &Manifest, selected: Vec<usize>, out: &Path) -> (usize, Vec<usize>) {
    let mut ids = std::collections::HashSet::new();
    let mut done = 0usize;
    let mut todo: Vec<usize> = Vec::new();
    for i in selected {
        let Some(case) = manifest.case(i) else { continue };
        if !ids.insert(case.id.clone()) {
            continue;
        }
        if store::is_done(out, &case) {
            done += 1;
        } else {
            todo.push(i);
        }
    }
    (done, todo)
}

/// Play the `todo` cases, `opts.jobs` at a time, until done or stopped; each case's outcome by
/// its index, in the order they ended.
fn play_cases(manifest: &Manifest, todo: &[usize], opts: &RunOptions) -> Vec<(usize, Outcome)> {
    let bar = progress_bar(todo.len(), opts.plain);
    let next = AtomicUsize::new(0);
    let outcomes: Mutex<Vec<(usize, Outcome)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..opts.jobs.clamp(1, todo.len().max(1)) {
            s.spawn(|| loop {
                if STOP.load(Ordering::SeqCst) {
                    break;
                }
                let k = next.fetch_add(1, Ordering::SeqCst);
                let Some(case) = todo.get(k).and_then(|&i| manifest.case(i)) else { break };
                let started = Instant::now();
                let outcome = play_case(&case, &opts.out, &opts.exe);
                let line = describe(&case, &outcome, started.elapsed().as_secs_f64(), &opts.out);
                match &bar {
                    Some(b) => {
                        b.println(line);
                        b.inc(1);
                    }
                    None => crate::outln!("[{}/{}] {line}", k + 1, todo.len()),
                }
                if let Ok(mut o) = outcomes.lock() {
                    o.push((case.index, outcome));
                }
            });
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    outcomes.into_inner().unwrap_or_default()
}

/// Hold `case`'s lock (DIR/cases/<id>/case.lock), creating its folder.
fn lock_case(out: &Path, case: &Case) -> Result<std::fs::File, store::LockError> {
    let dir = store::case_dir(out, &case.id);
    std::fs::create_dir_all(&dir).map_err(store::LockError::Io)?;
    store::try_lock(&dir.join("case.lock"), true)
}

fn progress_bar(len: usize, plain: bool) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    if plain || len == 0 || !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new(len as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{bar:40} {pos}/{len} cases  {elapsed_precise} elapsed, ETA {eta_precise}",
    ) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_secs(1));
    Some(bar)
}

/// One line about a finished case.
fn describe(case: &Case, outcome: &Outcome, secs: f64, out: &Path) -> String {
    let what: Vec<String> = case.varied.iter().map(|k| format!("{k}={}", case.cell(k))).collect();
    let head = format!("case {} [{}] {}", case.index, case.id, what.join(" "));
    match outcome {
        Outcome::Skipped => format!("{head}: skipped"),
        Outcome::Ok => {
            let r = store::read_result(out, &case.id).unwrap_or(Value::Null);
            let m = |k: &str| r.pointer(&format!("/metrics/{k}")).and_then(Value::as_f64);
            format!(
                "{head}: ok in {secs:.1} s, {} frames, mean e_t {} m, mean e_r {} deg{}",
                r.pointer("/metrics/frames").cloned().unwrap_or(Value::Null),
                m("mean_et_m").map_or("-".into(), |x| format!("{x:.4}")),
                m("mean_er_deg").map_or("-".into(), |x| format!("{x:.2}")),
                r.get("real_time_factor")
                    .and_then(Value::as_f64)
                    .map_or(String::new(), |f| format!(", run at {f:.2}x real time")),
            )
        }
        Outcome::Failed { stage, code } => format!(
            "{head}: FAILED in {stage} (exit {}) after {secs:.1} s; see {}",
            code.map_or("by signal".into(), |c| c.to_string()),
            store::case_dir(out, &case.id).display()
        ),
    }
}

/// The first line of a `cases.json` written for a manifest with this fingerprint.
fn index_head(fingerprint: &str) -> String {
    format!("{{\"fingerprint\":\"{fingerprint}\",")
}

/// DIR/manifest.toml and DIR/cases.json: what the folder's cases are (collect reads these).
/// The index is streamed case by case (never the whole grid in memory) and starts with the
/// manifest's fingerprint; an array task (`only_if_changed`) leaves an index with the same
/// fingerprint as it is instead of writing every case again.
fn write_index(
    manifest: &Manifest,
    text: &str,
    out: &Path,
    only_if_changed: bool,
) -> io::Result<()> {
    let head = index_head(&manifest.fingerprint());
    let index = out.join("cases.json");
    if only_if_changed {
        let first = std::fs::File::open(&index).ok().and_then(|f| {
            let mut line = String::new();
            io::BufReader::new(f.take(4096)).read_line(&mut line).ok()?;
            Some(line)
        });
        if first.is_some_and(|l| l.trim_end() == head) {
            return Ok(());
        }
    }
    write_atomic(&out.join("manifest.toml"), text.as_bytes())?;
    let tmp = store::temp_path(&index);
    let write = || -> io::Result<()> {
        let mut w = io::BufWriter::new(std::fs::File::create(&tmp)?);
        writeln!(w, "{head}")?;
        writeln!(w, "\"name\":{},", json!(manifest.name))?;
        writeln!(w, "\"varied\":{},", json!(manifest.varied))?;
        writeln!(w, "\"cases\":[")?;
        for (k, c) in manifest.cases().enumerate() {
            let sep = if k + 1 < manifest.len() { "," } else { "" };
            let row = json!({ "index": c.index, "id": c.id, "definition": c.definition() });
            writeln!(w, "{row}{sep}")?;
        }
        writeln!(w, "]}}")?;
        let f = w.into_inner().map_err(io::IntoInnerError::into_error)?;
        f.sync_all()?;
        std::fs::rename(&tmp, &index)
    };
    let r = write();
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// A stage that ended badly: its name, exit code (None: killed by a signal) and output tail.
struct StageFailure {
    stage: &'static str,
    code: Option<i32>,
    tail: String,
}

/// Run `exe ARGS` with stderr into `log` and stdout into `stdout` (or `log` too); Ok(()) on exit 0.
/// The child runs in a process group of its own and ends with this process
/// ([`super::child::run`]); a stage is not started once Ctrl-C was pressed.
fn stage(
    exe: &Path,
    stage: &'static str,
    args: &[String],
    log: &Path,
    stdout: Option<&Path>,
) -> Result<(), StageFailure> {
    let fail = |code: Option<i32>, extra: String| StageFailure {
        stage,
        code,
        tail: format!("{extra}{}", store::tail(log, TAIL_CHARS)),
    };
    if STOP.load(Ordering::SeqCst) {
        return Err(StageFailure {
            stage,
            code: Some(i32::from(crate::exit::OPERATOR_STOP)),
            tail: "not started: the campaign was interrupted (Ctrl-C)".into(),
        });
    }
    let err =
        std::fs::File::create(log).map_err(|e| fail(None, format!("{}: {e}\n", log.display())))?;
    let out = match stdout {
        Some(p) => std::fs::File::create(p),
        None => err.try_clone(),
    }
    .map_err(|e| fail(None, format!("{e}\n")))?;
    let mut cmd = Command::new(exe);
    cmd.args(args).stdin(Stdio::null()).stdout(out).stderr(err);
    let status = super::child::run(cmd)
        .map_err(|e| fail(None, format!("cannot start {}: {e}\n", exe.display())))?;
    if status.success() {
        Ok(())
    } else {
        Err(fail(status.code(), String::new()))
    }
}

fn s(x: impl ToString) -> String {
    x.to_string()
}

/// `hitl plan` arguments of a case (the trajectory goes to `out`).
pub(crate) fn plan_args(case: &Case, out: &Path) -> Result<(Vec<String>, Option<String>), String> {
    let preset = case.text("preset").unwrap_or("flyaround").to_string();
    let range = case.number("range_m").unwrap_or(10.0);
    let every = case.number("capture_every_s").unwrap_or(0.5);
    let k = ((every * DEFAULT_WAYPOINT_RATE_HZ).round() as u64).max(1);
    let mut a = vec![
        s("plan"),
        s("--preset"),
        preset.clone(),
        s("--range-m"),
        s(range),
        s("--duration-s"),
        s(case.number("duration_s").unwrap_or(20.0)),
        s("--capture-every"),
        s(k),
        s("--out"),
        s(out.display()),
        s("--json"),
    ];
    let mut arc = case.text("arc_deg").map(str::to_string);
    if let Some(w) = case.text("sun_phase_deg") {
        let window = super::manifest::parse_window(w).ok_or(format!("sun_phase_deg {w:?}"))?;
        let (from, to) = phase::arc_for_window(&preset, range, window)?;
        arc = Some(format!("{from}:{to}"));
    }
    if case.text("phase_angle_deg").is_some() {
        if case.text("sun_phase_deg").is_some() {
            return Err("sun_phase_deg picks the arc under the default Sun, phase_angle_deg the \
                        Sun for the arc: give one"
                .into());
        }
        let sun = case_sun(case)?;
        let [x, y, z] = sun.sun_eci;
        a.extend([s("--sun-eci"), format!("{x},{y},{z}")]);
    }
    if let Some(arc) = &arc {
        a.extend([s("--arc"), arc.clone()]);
    }
    if let Some(c) = case.text("config") {
        a.extend([s("--config"), s(c)]);
    }
    Ok((a, arc))
}

/// The Sun a case plays under and the phase angles its arc sees (`phase_angle_deg` chooses the
/// Sun; `sun_phase_deg` chooses the arc under the default Sun).
pub(super) fn case_sun(case: &Case) -> Result<phase::CaseSun, String> {
    let preset = case.text("preset").unwrap_or("flyaround");
    let range = case.number("range_m").unwrap_or(10.0);
    let window = |key: &str| -> Result<Option<(f64, f64)>, String> {
        case.text(key)
            .map(|w| super::manifest::parse_window(w).ok_or(format!("{key} {w:?}")))
            .transpose()
    };
    let mut arc = window("arc_deg")?;
    if let Some(w) = window("sun_phase_deg")? {
        arc = Some(phase::arc_for_window(preset, range, w)?);
    }
    phase::case_sun(preset, range, arc, window("phase_angle_deg")?)
}

/// The real-time factor a simulated-clock run printed in its log (`simulated clock: S s simulated
/// in W s (Fx real time)`); `None` on the host's clock or without the log.
fn real_time_factor(log: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(log).ok()?;
    let line = text.lines().rev().find(|l| l.starts_with("simulated clock:"))?;
    // After the host seconds: a stalled run's line goes on with "wait(s) gave up".
    let (_, rest) = line.split_once(" s (")?;
    rest.split_once("x real time")?.0.trim().parse().ok()
}

/// `hitl run` arguments of a case.
pub(crate) fn run_args(case: &Case, plan: &Path, record: &Path) -> Vec<String> {
    let mut a = vec![
        s("run"),
        s(plan.display()),
        s("--record"),
        s(record.display()),
        s("--camera"),
        s("sim"),
        s("--light"),
        s("sim"),
        s("--camera-preset"),
        s(case.text("camera_preset").unwrap_or("wfov")),
        s("--perception"),
        s(case.text("perception").unwrap_or("icp")),
        s("--target-model"),
        s(case.text("target").unwrap_or("asymmetric")),
        s("--plain"),
        s("--clock"),
        s(case.text("clock").unwrap_or("sim")),
    ];
    if let Some(size) = case.text("camera_size") {
        a.extend([s("--camera-size"), s(size)]);
    }
    if let Some(kind) = case.text("scene_kind") {
        a.extend([s("--scene-kind"), s(kind)]);
    }
    if let Some(c) = case.text("config") {
        a.extend([s("--config"), s(c)]);
    }
    if let Some(p) = case.params.get("rt_priority").and_then(Value::as_i64) {
        a.extend([s("--rt-priority"), s(p)]);
    }
    if let Some(n) = case.params.get("reregister_every").and_then(Value::as_u64) {
        a.extend([s("--reregister-every"), s(n)]);
    }
    a
}

/// `hitl eval` (stdout: one JSON object) into `json_out` atomically.
fn eval_stage(
    exe: &Path,
    name: &'static str,
    args: &[String],
    json_out: &Path,
    log: &Path,
) -> Result<Value, StageFailure> {
    let fail = |tail: String| StageFailure { stage: name, code: None, tail };
    let tmp = store::temp_path(json_out);
    stage(exe, name, args, log, Some(&tmp))?;
    let bytes = store::read_regular(&tmp, store::MAX_RESULT_BYTES)
        .map_err(|e| fail(format!("hitl eval's output {}: {e}", tmp.display())))?;
    let _ = std::fs::remove_file(&tmp);
    let v: Value = serde_json::from_slice(&bytes)
        .map_err(|e| fail(format!("hitl eval printed no JSON object: {e}")))?;
    write_atomic(json_out, format!("{v}\n").as_bytes())
        .map_err(|e| fail(format!("{}: {e}", json_out.display())))?;
    Ok(v)
}

/// Play one case and write its result; stages whose output already exists are not repeated.
pub fn play_case(case: &Case, out: &Path, exe: &Path) -> Outcome {
    let dir = store::case_dir(out, &case.id);
    let t0 = Instant::now();
    let mut result = json!({
        "id": case.id,
        "index": case.index,
        "definition": case.definition(),
    });
    let outcome = play_stages(case, &dir, exe, &mut result);
    // Whatever ended the case, no temporary file of it stays behind (this process is the only
    // writer of the case's folder: see the locks in `run`).
    store::remove_stale_temps(&dir);
    let outcome = match outcome {
        Ok(()) => {
            result["status"] = json!("ok");
            Outcome::Ok
        }
        Err(f) => {
            result["status"] = json!("failed");
            result["failed_stage"] = json!(f.stage);
            result["exit_code"] = json!(f.code);
            result["stderr_tail"] = json!(f.tail);
            Outcome::Failed { stage: f.stage.to_string(), code: f.code }
        }
    };
    result["wall_s"] = json!(t0.elapsed().as_secs_f64());
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    result["finished_unix_s"] = json!(unix);
    if let Err(e) = write_atomic(&dir.join("result.json"), format!("{result:#}\n").as_bytes()) {
        crate::errln!("hitl campaign run: {}: {e}", dir.display());
        return Outcome::Failed { stage: "result".into(), code: None };
    }
    outcome
}

fn play_stages(
    case: &Case,
    dir: &Path,
    exe: &Path,
    result: &mut Value,
) -> Result<(), StageFailure> {
    let io = |e: std::io::Error| StageFailure { stage: "setup", code: None, tail: e.to_string() };
    std::fs::create_dir_all(dir).map_err(io)?;
    store::remove_stale_temps(dir);
    let _ = std::fs::remove_file(dir.join("result.json"));

    // 1. plan
    let plan = dir.join("plan.npz");
    let tmp = store::temp_path(&plan);
    let (args, arc) = plan_args(case, &tmp).map_err(|e| StageFailure {
        stage: "plan",
        code: Some(2),
        tail: e,
    })?;
    result["arc_deg"] = json!(arc);
    let plan_json = dir.join("plan.json");
    if !plan.exists() || !plan_json.exists() {
        let tmp_json = store::temp_path(&plan_json);
        stage(exe, "plan", &args, &dir.join("plan.log"), Some(&tmp_json))?;
        std::fs::rename(&tmp, &plan).map_err(io)?;
        std::fs::rename(&tmp_json, &plan_json).map_err(io)?;
    }
    // The planned Sun phase range, for the tables (hitl plan --json's summary).
    let summary: Value = std::fs::read_to_string(&plan_json)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null);
    result["planned_sun_phase_deg"] =
        summary.pointer("/summary/sun_phase_deg").cloned().unwrap_or(Value::Null);

    // 2. run (SITL, recorded); a failed run keeps its recording as run-failed.mcap for a look,
    // and the case is played again on the next campaign run.
    let rec = dir.join("run.mcap");
    if !rec.exists() {
        let tmp = store::temp_path(&rec);
        let r = stage(exe, "run", &run_args(case, &plan, &tmp), &dir.join("run.log"), None);
        match r {
            Ok(()) => std::fs::rename(&tmp, &rec).map_err(io)?,
            Err(f) => {
                let _ = std::fs::rename(&tmp, dir.join("run-failed.mcap"));
                return Err(f);
            }
        }
    }
    let _ = std::fs::remove_file(dir.join("run-failed.mcap"));
    result["real_time_factor"] =
        real_time_factor(&dir.join("run.log")).map_or(Value::Null, |f| json!(f));

    // 3. eval: the run's own estimates (ground-truth mesh), then the decimated mesh if asked.
    let rec_s = s(rec.display());
    let gt_args = vec![s("eval"), rec_s.clone(), s("--json")];
    let gt =
        eval_stage(exe, "eval", &gt_args, &dir.join("eval-gt.json"), &dir.join("eval-gt.log"))?;
    let metrics = match case.mesh_faces() {
        None => {
            write_atomic(&dir.join("eval.json"), format!("{gt}\n").as_bytes()).map_err(io)?;
            gt.clone()
        }
        Some(n) => {
            let backend = match case.text("perception") {
                None | Some("none") => "icp",
                Some(p) => p,
            };
            let mut a = gt_args.clone();
            a.extend([s("--backend"), s(backend), s("--mesh-faces"), s(n)]);
            if let Some(t) = case.text("target") {
                a.extend([s("--target"), s(t)]);
            }
            eval_stage(exe, "eval-mesh", &a, &dir.join("eval.json"), &dir.join("eval.log"))?
        }
    };
    result["metrics"] = metrics;
    result["baseline"] = gt;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::campaign::manifest::parse;

    fn clock_of(manifest: &str) -> String {
        let m = parse(manifest, Path::new("/m"), "m").expect("manifest");
        let case = m.cases().next().expect("a case");
        let a = run_args(&case, Path::new("p.npz"), Path::new("r.mcap"));
        let i = a.iter().position(|x| x == "--clock").expect("--clock passed");
        a[i + 1].clone()
    }

    #[test]
    fn a_case_runs_on_the_simulated_clock_unless_its_manifest_says_realtime() {
        assert_eq!(clock_of("[run]\nrange_m = 5\n"), "sim");
        assert_eq!(clock_of("[run]\nrange_m = 5\nclock = \"realtime\"\n"), "realtime");
        assert!(parse("[run]\nclock = \"wall\"\n", Path::new("/m"), "m").is_err());
        assert!(parse("[run]\n[matrix]\nclock = [\"sim\", \"realtime\"]\n", Path::new("/m"), "m")
            .is_err());
    }

    #[test]
    fn the_real_time_factor_is_read_from_the_run_summary() {
        let dir = tempfile::tempdir().expect("tempdir");
        let log = dir.path().join("run.log");
        std::fs::write(
            &log,
            "completed\nsimulated clock: 12.000 s simulated in 2.000 s (6.00x real time)\n",
        )
        .expect("write");
        assert_eq!(real_time_factor(&log), Some(6.0));
        let stalled = "simulated clock: 42.760 s simulated in 88.367 s (0.48x real time); 1 \
                       lockstep wait(s) gave up after 60 s: this run may not repeat exactly\n";
        std::fs::write(&log, stalled).expect("write");
        assert_eq!(real_time_factor(&log), Some(0.48));
        std::fs::write(&log, "completed\ncaptures 3\n").expect("write");
        assert_eq!(real_time_factor(&log), None);
    }
}
