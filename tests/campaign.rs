//! `hitl campaign` end to end on a tiny 4-case manifest (3 s fly-arounds, 96x64 frames): run,
//! interrupt after the first case, resume (done cases skipped), rerun (everything skipped, in
//! seconds), collect (CSV rows and values); the sbatch script run as an array task plays its
//! case; unknown keys exit 2 naming the key; a failing case is recorded, not fatal.

mod common;

use common::{hitl, SHARED_VM_LAB};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Two ranges x two targets, 3 s each over a 20 deg arc (a whole orbit needs about 40 s at the
/// arm's speed limits) with a capture every 0.5 s.
fn tiny_manifest(dir: &Path) -> std::path::PathBuf {
    let m = dir.join("tiny.toml");
    std::fs::write(
        &m,
        format!(
            "[campaign]\nname = \"tiny\"\n\
             [run]\npreset = \"flyaround\"\nduration_s = 3\ncapture_every_s = 0.5\n\
             arc_deg = \"420:440\"\n\
             camera_preset = \"wfov\"\ncamera_size = \"96x64\"\nperception = \"icp\"\n\
             config = \"{SHARED_VM_LAB}\"\n\
             [matrix]\nrange_m = [5, 7]\ntarget = [\"asymmetric\", \"one-plane\"]\n"
        ),
    )
    .expect("manifest");
    m
}

fn results(out: &Path) -> Vec<std::path::PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(out.join("cases"))
        .map(|d| d.flatten().map(|e| e.path().join("result.json")).filter(|p| p.exists()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

/// How many cases have a result that says ok.
fn ok_results(out: &Path) -> usize {
    results(out)
        .iter()
        .filter(|p| std::fs::read_to_string(p).is_ok_and(|t| t.contains("\"status\": \"ok\"")))
        .count()
}

fn text(o: &std::process::Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn run_interrupt_resume_rerun_collect() {
    let d = tempfile::tempdir().expect("tempdir");
    let m = tiny_manifest(d.path());
    let out = d.path().join("out");
    let (ms, os) = (m.to_str().expect("utf-8"), out.to_str().expect("utf-8"));

    let list = hitl(&["campaign", "list", ms]);
    assert_eq!(list.status.code(), Some(0), "{}", text(&list));
    assert!(String::from_utf8_lossy(&list.stdout).contains("4 cases"), "{}", text(&list));

    // Run, and kill the campaign process once the first case is done.
    let mut child = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["campaign", "run", ms, "--out", os, "--jobs", "1", "--plain"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start campaign");
    let t0 = Instant::now();
    while results(&out).is_empty() {
        assert!(t0.elapsed() < Duration::from_secs(240), "no case finished in 240 s");
        if let Ok(Some(s)) = child.try_wait() {
            panic!("campaign ended before it was interrupted: {s}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    child.kill().expect("kill campaign");
    let _ = child.wait();
    let after_kill = results(&out).len();
    assert!((1..4).contains(&after_kill), "{after_kill} cases done when killed");

    // Resume: the finished cases are skipped, the rest played. A case an interlock stopped (a
    // loaded 2-core box can starve the stub's physics) is failed, recorded, and played again by
    // the next resume, so resume until every case is done (at most three times).
    // The killed campaign's `hitl run` child finishes its controlled stop first (within 5 s:
    // tests/campaign_guards.rs) and holds the folder's lock until then; a resume before that is
    // refused, as it must be while the arm may still move.
    let mut resumes = 0;
    let killed_at = Instant::now();
    loop {
        let done_before = ok_results(&out);
        let resumed = hitl(&["campaign", "run", ms, "--out", os, "--jobs", "1", "--plain"]);
        let said = text(&resumed);
        if resumes == 0
            && said.contains("is in use")
            && killed_at.elapsed() < Duration::from_secs(10)
        {
            std::thread::sleep(Duration::from_millis(200));
            continue;
        }
        assert!(said.contains(&format!("{done_before} already done")), "{said}");
        assert!(said.contains(&format!("{} played", 4 - done_before)), "{said}");
        resumes += 1;
        match resumed.status.code() {
            Some(0) => break,
            Some(1) if resumes < 3 => assert!(said.contains("FAILED in"), "{said}"),
            _ => panic!("resume {resumes}: {said}"),
        }
    }
    assert_eq!(ok_results(&out), 4);

    // Rerun: nothing to do, in seconds.
    let t = Instant::now();
    let rerun = hitl(&["campaign", "run", ms, "--out", os, "--plain"]);
    assert_eq!(rerun.status.code(), Some(0), "{}", text(&rerun));
    assert!(text(&rerun).contains("4 already done, 0 to run"), "{}", text(&rerun));
    assert!(t.elapsed() < Duration::from_secs(10), "rerun took {:?}", t.elapsed());

    // Collect: one row per case, in case order, with the paper's metrics.
    let c = hitl(&["campaign", "collect", os]);
    assert_eq!(c.status.code(), Some(0), "{}", text(&c));
    let csv = std::fs::read_to_string(out.join("results.csv")).expect("results.csv");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let order: Vec<(&str, &str)> =
        rows.iter().map(|r| (r[col("range_m")], r[col("target")])).collect();
    assert_eq!(
        order,
        vec![("5", "asymmetric"), ("5", "one-plane"), ("7", "asymmetric"), ("7", "one-plane")]
    );
    for r in &rows {
        assert_eq!(r[col("status")], "ok", "{csv}");
        let frames: u32 = r[col("frames")].parse().expect("frames");
        assert_eq!(frames, 7, "3 s at one capture per 0.5 s: {csv}");
        let failures: u32 = r[col("failures")].parse().expect("failures");
        assert!(failures < frames, "{csv}");
        let range: f64 = r[col("range_m")].parse().expect("range");
        for k in ["mean_et_m", "median_et_m", "std_et_m"] {
            let v: f64 = r[col(k)].parse().expect(k);
            assert!(v >= 0.0 && v < 0.05 * range, "{k} {v} at {range} m: {csv}");
        }
        let er: f64 = r[col("mean_er_deg")].parse().expect("e_r");
        assert!((0.0..20.0).contains(&er), "mean e_r {er}: {csv}");
        // Nothing decimated: the estimator is the ground-truth-mesh baseline.
        assert_eq!(r[col("mean_et_m")], r[col("gt_mean_et_m")]);
    }
    assert!(out.join("plots/range.svg").exists(), "range plot");
    let svg = std::fs::read_to_string(out.join("plots/range.svg")).expect("svg");
    assert!(svg.contains("one-plane"), "legend names the targets");
}

#[test]
fn unknown_keys_are_refused_naming_them() {
    let d = tempfile::tempdir().expect("tempdir");
    let m = d.path().join("bad.toml");
    std::fs::write(&m, "[run]\nduration_s = 3\n[matrix]\nrange_km = [5]\n").expect("write");
    let o = hitl(&["campaign", "run", m.to_str().expect("utf-8"), "--out", "/nonexistent/x"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("`range_km`"), "{}", text(&o));
    assert!(!Path::new("/nonexistent/x").exists());
}

/// Every preset in campaigns/ loads and expands to the paper's study: a preset edited into an
/// unknown key or a wrong matrix would otherwise only show when someone runs it for an hour.
#[test]
fn the_presets_load_with_their_case_counts() {
    let expected = [
        ("rq2-mesh.toml", 20),
        ("rq2-mesh-ci.toml", 2),
        ("rq3-range.toml", 40),
        ("rq3-range-ci.toml", 2),
        ("rq4-illumination.toml", 30),
        ("rq4-illumination-ci.toml", 4),
        ("sitl-table.toml", 24),
    ];
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("campaigns");
    let mut found: Vec<String> = std::fs::read_dir(&dir)
        .expect("campaigns/")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    found.sort();
    let mut listed: Vec<String> = expected.iter().map(|(n, _)| n.to_string()).collect();
    listed.sort();
    assert_eq!(found, listed, "a preset without an expected case count here");
    for (name, cases) in expected {
        let o = hitl(&["campaign", "list", dir.join(name).to_str().expect("utf-8")]);
        assert_eq!(o.status.code(), Some(0), "{name}: {}", text(&o));
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(
            out.lines().next().is_some_and(|l| l.ends_with(&format!(": {cases} cases"))),
            "{name}: {out}"
        );
        assert_eq!(out.lines().count(), cases + 1, "{name}: {out}");
    }
    // The illumination study plays where the Sun moves.
    let rq4 = std::fs::read_to_string(dir.join("rq4-illumination.toml")).expect("rq4");
    assert!(rq4.contains("scene_kind = \"orbit\""));
}

/// RQ4 plays the paper's five phase-angle regions, each with both estimators: `campaign list
/// --json` gives every case's planned phase angles, and each region's cases stay inside it.
#[test]
fn the_rq4_preset_covers_the_five_phase_regions() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("campaigns");
    let o = hitl(&[
        "campaign",
        "list",
        "--json",
        dir.join("rq4-illumination.toml").to_str().expect("utf-8"),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let cases = v["cases"].as_array().expect("cases");
    let regions = [(0.0, 36.0), (36.0, 72.0), (72.0, 108.0), (108.0, 144.0), (144.0, 180.0)];
    for (from, to) in regions {
        let inside: Vec<&serde_json::Value> = cases
            .iter()
            .filter(|c| c["params"]["phase_angle_deg"] == format!("{from}:{to}"))
            .collect();
        assert_eq!(inside.len(), 6, "{from}:{to}: three targets times two estimators");
        for c in inside {
            let lo = c["phase_angle_deg"][0].as_f64().expect("phase range");
            let hi = c["phase_angle_deg"][1].as_f64().expect("phase range");
            assert!(from <= lo && lo < hi && hi <= to, "{from}:{to}: the arc sees {lo}-{hi}");
            assert_eq!(c["sun_eci"].as_array().map(Vec::len), Some(3), "{c}");
        }
    }
    for p in ["icp", "mono"] {
        assert_eq!(cases.iter().filter(|c| c["params"]["perception"] == p).count(), 15, "{p}");
    }
}

#[test]
fn sbatch_script_plays_its_case_and_failures_are_recorded() {
    let d = tempfile::tempdir().expect("tempdir");
    let m = d.path().join("two.toml");
    // Case 0 plays; case 1 names a target that does not exist and fails in `hitl run`.
    std::fs::write(
        &m,
        format!(
            "[run]\nduration_s = 3\ncapture_every_s = 1\narc_deg = \"420:440\"\ncamera_size = \"96x64\"\nrange_m = 5\n\
             config = \"{SHARED_VM_LAB}\"\n[matrix]\ntarget = [\"one-plane\", \"no-such-target\"]\n"
        ),
    )
    .expect("write");
    let out = d.path().join("out");
    let (ms, os) = (m.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    let w = hitl(&["campaign", "slurm", ms, "--out", os, "--limit", "3"]);
    assert_eq!(w.status.code(), Some(0), "{}", text(&w));
    let script = out.join("slurm/two.sbatch");
    let body = std::fs::read_to_string(&script).expect("script");
    assert!(body.contains("#SBATCH --array=0-1%3"), "{body}");

    // As Slurm runs array task 0: bash, SLURM_ARRAY_TASK_ID set, nothing else (a second try if
    // an interlock stopped the run on a loaded box, as a requeued task would).
    let task0 = || {
        Command::new("bash")
            .arg(&script)
            .env("SLURM_ARRAY_TASK_ID", "0")
            .env_remove("LD_LIBRARY_PATH")
            .stdin(Stdio::null())
            .output()
            .expect("bash")
    };
    let mut task = task0();
    if task.status.code() == Some(1) {
        task = task0();
    }
    assert_eq!(task.status.code(), Some(0), "{}", text(&task));
    let done = results(&out);
    assert_eq!(done.len(), 1, "task 0 plays case 0 only");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&done[0]).expect("read")).expect("json");
    assert_eq!(r["status"], "ok", "{r:#}");
    assert_eq!(r["index"], 0);
    assert_eq!(r["metrics"]["frames"], 4, "{r:#}");

    // Task 1 fails in the run stage: recorded with its exit code and stderr, exit 1.
    let task = Command::new("bash")
        .arg(&script)
        .env("SLURM_ARRAY_TASK_ID", "1")
        .stdin(Stdio::null())
        .output()
        .expect("bash");
    assert_eq!(task.status.code(), Some(1), "{}", text(&task));
    let failed = results(&out)
        .into_iter()
        .map(|p| {
            serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(p).expect("read"))
                .expect("json")
        })
        .find(|r| r["index"] == 1)
        .expect("case 1 result");
    assert_eq!(failed["status"], "failed", "{failed:#}");
    assert_eq!(failed["failed_stage"], "run");
    assert_eq!(failed["exit_code"], 2);
    assert!(
        failed["stderr_tail"].as_str().is_some_and(|s| s.contains("no-such-target")),
        "{failed:#}"
    );
}
