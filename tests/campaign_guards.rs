//! `hitl campaign` refuses what it cannot do safely, through the commands a user types: grids past
//! the case limit (counted, never built), values the `hitl plan` / `hitl run` flags would refuse,
//! empty manifests, Slurm fields that could leave their line or names that could leave `--out`,
//! corrupt results; and it keeps what it runs in hand: a held folder is refused to a second
//! campaign, and a campaign's children end with it (`kill -9`) or stop with it (Ctrl-C). One test
//! per row of docs/campaigns.md's exit-code table lives here or in tests/campaign.rs.

mod common;

use common::{hitl, SHARED_VM_LAB};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Tests that play SITL runs take turns: two at once on a 2-core machine starve the loops.
static PLAYING: Mutex<()> = Mutex::new(());

fn playing() -> std::sync::MutexGuard<'static, ()> {
    PLAYING.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn write(dir: &Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, body).expect("write");
    p
}

/// `[matrix]` of `keys` numeric axes with ten values each (10^keys cases).
fn grid(keys: usize) -> String {
    let axes: [(&str, &str); 12] = [
        ("range_m", "[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]"),
        ("duration_s", "[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]"),
        ("capture_every_s", "[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]"),
        ("reregister_every", "[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]"),
        ("mesh_faces", "[10, 11, 12, 13, 14, 15, 16, 17, 18, 19]"),
        ("target", r#"["a", "b", "c", "d", "e", "f", "g", "h", "i", "j"]"#),
        (
            "arc_deg",
            r#"["0:10", "1:10", "2:10", "3:10", "4:10", "5:10", "6:10", "7:10", "8:10", "9:10"]"#,
        ),
        (
            "perception",
            r#"["onnx:a", "onnx:b", "onnx:c", "onnx:d", "onnx:e", "onnx:f", "onnx:g", "onnx:h", "onnx:i", "onnx:j"]"#,
        ),
        (
            "sun_phase_deg",
            r#"["0:1", "1:2", "2:3", "3:4", "4:5", "5:6", "6:7", "7:8", "8:9", "9:10"]"#,
        ),
        (
            "camera_size",
            r#"["8x8", "9x9", "10x10", "11x11", "12x12", "13x13", "14x14", "15x15", "16x16", "17x17"]"#,
        ),
        ("scene_kind", r#"["a", "b", "c", "d", "e", "f", "g", "h", "i", "j"]"#),
        ("camera_preset", r#"["a", "b", "c", "d", "e", "f", "g", "h", "i", "j"]"#),
    ];
    let mut t = String::from("[matrix]\n");
    for (k, v) in axes.iter().take(keys) {
        t += &format!("{k} = {v}\n");
    }
    t
}

#[test]
fn grids_past_the_case_limit_are_refused_at_once() {
    let d = tempfile::tempdir().expect("tempdir");
    for (keys, count) in [(6, "1000000 cases"), (12, "1000000000000 cases")] {
        let m = write(d.path(), &format!("g{keys}.toml"), &grid(keys));
        let out = d.path().join(format!("out{keys}"));
        for args in [
            vec!["campaign", "list", s(&m)],
            vec!["campaign", "run", s(&m), "--out", s(&out), "--index", "999999"],
            vec!["campaign", "slurm", s(&m), "--out", s(&out)],
        ] {
            let t = Instant::now();
            let o = hitl(&args);
            assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
            let said = String::from_utf8_lossy(&o.stderr);
            assert!(said.contains(count) && said.contains("limit of 100000"), "{args:?}: {said}");
            assert!(t.elapsed() < Duration::from_secs(5), "{args:?} took {:?}", t.elapsed());
            assert!(!out.exists(), "{args:?} wrote {}", out.display());
        }
    }
}

/// At the limit: `list` streams 100 000 cases, and `run --index 99999` plays that case alone from
/// its index (the grid is never built): its result is the case `list` printed last.
#[test]
fn the_last_case_of_a_full_grid_plays_from_its_index() {
    let d = tempfile::tempdir().expect("tempdir");
    // 10^5 cases; every one fails fast (the target does not exist), which is all this needs.
    let body = format!("[run]\ntarget = \"no-such-target\"\n{}", grid(5));
    let m = write(d.path(), "limit.toml", &body);
    let list = hitl(&["campaign", "list", s(&m)]);
    assert_eq!(list.status.code(), Some(0), "{}", text(&list));
    let stdout = String::from_utf8_lossy(&list.stdout);
    assert_eq!(stdout.lines().count(), 100_001);
    let last = stdout.lines().last().expect("last line");
    let id = last.split_whitespace().nth(1).expect("id");
    assert!(last.trim_start().starts_with("99999 "), "{last}");

    let _turn = playing();
    let out = d.path().join("out");
    let o = hitl(&["campaign", "run", s(&m), "--out", s(&out), "--index", "99999", "--plain"]);
    assert_eq!(o.status.code(), Some(1), "the case fails: {}", text(&o));
    let r: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.join("cases").join(id).join("result.json")).expect("result"),
    )
    .expect("json");
    assert_eq!(r["index"], 99999);
    assert_eq!(std::fs::read_dir(out.join("cases")).expect("cases").count(), 1);
}

#[test]
fn manifest_values_are_checked_when_loaded() {
    let d = tempfile::tempdir().expect("tempdir");
    for (body, key, says) in [
        ("[run]\ncamera_size = \"0x0\"\n", "`camera_size`", "--camera-size"),
        ("[run]\npreset = \"warp\"\n", "`preset`", "--preset"),
        ("[matrix]\nscene_kind = [\"lab\", \"moon\"]\n", "`scene_kind`", "--scene-kind"),
        ("[run]\nperception = \"magic\"\n", "`perception`", "--perception"),
        ("[run]\ncamera_preset = \"xfov\"\n", "`camera_preset`", "--camera-preset"),
        ("[run]\nrt_priority = -1\n", "`rt_priority`", "0 (the normal scheduler) to 99"),
        ("[run]\nrt_priority = 1000\n", "`rt_priority`", "0 (the normal scheduler) to 99"),
        ("[run]\nreregister_every = 0\n", "`reregister_every`", "at least 1"),
        ("[run]\narc_deg = \"10:10\"\n", "`arc_deg`", "FROM < TO"),
        ("[run]\nduration_s = 1e300\n", "`duration_s`", "waypoints"),
        ("", "no [run] or [matrix]", "empty manifest"),
        ("[campaign]\nname = \"../../../escaped\"\n[run]\nrange_m = 5\n", "campaign name", "/"),
        ("[campaign]\nname = \"a\\nb\"\n[run]\nrange_m = 5\n", "campaign name", "control"),
    ] {
        let m = write(d.path(), "m.toml", body);
        let o = hitl(&["campaign", "list", s(&m)]);
        assert_eq!(o.status.code(), Some(2), "{body:?}: {}", text(&o));
        let said = String::from_utf8_lossy(&o.stderr);
        assert!(said.contains(key) && said.contains(says), "{body:?}: {said}");
    }
}

/// `slurm` writes nothing it cannot say safely (exit 2), names refused before anything is
/// written; what it writes runs under bash as written; sbatch's refusal is exit 5.
#[test]
fn slurm_scripts_hold_only_checked_and_quoted_fields() {
    let d = tempfile::tempdir().expect("tempdir");
    let m = write(d.path(), "c.toml", "[run]\nrange_m = 5\n[matrix]\nduration_s = [3, 4]\n");
    let out = d.path().join("out");
    let refused = |extra: &[&str], says: &str| {
        let mut args = vec!["campaign", "slurm", s(&m), "--out", s(&out)];
        args.extend_from_slice(extra);
        let o = hitl(&args);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", text(&o));
        assert!(String::from_utf8_lossy(&o.stderr).contains(says), "{extra:?}: {}", text(&o));
        assert!(!out.join("slurm").exists(), "{extra:?} wrote a script");
    };
    refused(&["--partition", "debug\ntouch X"], "--partition");
    refused(&["--account", "lab; touch X"], "--account");
    refused(&["--mem", "4G\n#SBATCH --exclusive"], "--mem");
    refused(&["--limit", "0"], "--limit 0");
    refused(&["--cpus-per-task", "0"], "--cpus-per-task");
    refused(&["--time-min", "99999999"], "time limit");
    let mut bad_out = out.as_os_str().to_owned();
    bad_out.push("\nrm -rf x");
    let o = hitl(&["campaign", "slurm", s(&m), "--out", bad_out.to_str().expect("utf-8")]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    for name in ["../../../escaped", "a\\nb"] {
        let mm = write(
            d.path(),
            "n.toml",
            &format!("[campaign]\nname = \"{name}\"\n[run]\nrange_m = 5\n"),
        );
        let o = hitl(&["campaign", "slurm", s(&mm), "--out", s(&out)]);
        assert_eq!(o.status.code(), Some(2), "{name}: {}", text(&o));
    }
    assert!(!d.path().join("escaped.sbatch").exists() && !Path::new("/escaped.sbatch").exists());
    let long = write(d.path(), "long.toml", "[run]\nduration_s = 1e300\n");
    let o = hitl(&["campaign", "slurm", s(&long), "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));

    // Paths with spaces, quotes and `$` are quoted: the script runs the campaign on exactly
    // them (an index past the end: it answers at once, naming the manifest) and nothing else.
    let odd = d.path().join("it's a $HOME \"dir\"");
    std::fs::create_dir_all(&odd).expect("odd dir");
    let om = write(&odd, "c.toml", "[run]\nrange_m = 5\n[matrix]\nduration_s = [3, 4]\n");
    let oout = odd.join("out #1");
    let w = hitl(&["campaign", "slurm", s(&om), "--out", s(&oout), "--partition", "debug"]);
    assert_eq!(w.status.code(), Some(0), "{}", text(&w));
    let script = oout.join("slurm/c.sbatch");
    let body = std::fs::read_to_string(&script).expect("script");
    assert!(body.contains("#SBATCH --partition=debug\n"), "{body}");
    assert!(body.contains("#SBATCH --output=\""), "a directive with spaces is quoted: {body}");
    let task = Command::new("bash")
        .arg(&script)
        .current_dir(d.path())
        .env("SLURM_ARRAY_TASK_ID", "7")
        .stdin(Stdio::null())
        .output()
        .expect("bash");
    assert_eq!(task.status.code(), Some(2), "{}", text(&task));
    let said = String::from_utf8_lossy(&task.stderr);
    assert!(said.contains(&format!("--index 7 is out of range: {} has 2 cases", s(&om))), "{said}");

    // --submit: sbatch's refusal is exit 5.
    let bin = d.path().join("bin");
    std::fs::create_dir_all(&bin).expect("bin");
    write(&bin, "sbatch", "#!/bin/sh\necho 'sbatch: error: invalid partition' >&2\nexit 1\n");
    Command::new("chmod").arg("+x").arg(bin.join("sbatch")).status().expect("chmod");
    let o = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["campaign", "slurm", s(&m), "--out", s(&out), "--submit"])
        .env("PATH", format!("{}:/usr/bin:/bin", s(&bin)))
        .stdin(Stdio::null())
        .output()
        .expect("hitl");
    assert_eq!(o.status.code(), Some(5), "{}", text(&o));
    assert!(text(&o).contains("invalid partition"), "{}", text(&o));
}

/// Four cases that fail in `hitl plan` (too close to fit the arm): recorded, no temporary file
/// left, exit 1. Then their results are damaged four ways, and `collect` names each (exit 1).
#[test]
fn failed_stages_leave_no_temporaries_and_collect_names_corrupt_results() {
    let d = tempfile::tempdir().expect("tempdir");
    let o = hitl(&["campaign", "collect", s(d.path())]);
    assert_eq!(o.status.code(), Some(2), "not a campaign folder: {}", text(&o));

    let m = write(
        d.path(),
        "near.toml",
        "[run]\nrange_m = 1\nduration_s = 1\ncapture_every_s = 0.1\n\
         [matrix]\nmesh_faces = [100, 200, 300, 400]\n",
    );
    let out = d.path().join("out");
    let _turn = playing();
    let r = hitl(&["campaign", "run", s(&m), "--out", s(&out), "--plain"]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    let mut dirs: Vec<PathBuf> =
        std::fs::read_dir(out.join("cases")).expect("cases").flatten().map(|e| e.path()).collect();
    dirs.sort();
    assert_eq!(dirs.len(), 4);
    for dir in &dirs {
        for e in std::fs::read_dir(dir).expect("case").flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            assert!(!name.contains(".tmp"), "{} left {name}", dir.display());
        }
        let r: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("result.json")).expect("result"))
                .expect("json");
        assert_eq!(
            (r["status"].as_str(), r["failed_stage"].as_str()),
            (Some("failed"), Some("plan"))
        );
    }

    // Damage them: truncated, an unknown status, negative frames, a link to /dev/zero.
    let res = |i: usize| dirs[i].join("result.json");
    let whole = std::fs::read_to_string(res(0)).expect("read");
    std::fs::write(res(0), &whole[..whole.len() / 2]).expect("truncate");
    let edit = |i: usize, f: &dyn Fn(&mut serde_json::Value)| {
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(res(i)).expect("read")).expect("json");
        f(&mut v);
        std::fs::write(res(i), v.to_string()).expect("write");
    };
    edit(1, &|v| v["status"] = "weird".into());
    edit(2, &|v| {
        v["status"] = "ok".into();
        v["metrics"] = serde_json::json!({"frames": -5, "failures": 0, "mean_et_m": 0.1});
        v["baseline"] = v["metrics"].clone();
    });
    std::fs::remove_file(res(3)).expect("rm");
    std::os::unix::fs::symlink("/dev/zero", res(3)).expect("symlink");

    let t = Instant::now();
    let c = hitl(&["campaign", "collect", s(&out)]);
    assert!(t.elapsed() < Duration::from_secs(10), "collect took {:?}", t.elapsed());
    assert_eq!(c.status.code(), Some(1), "{}", text(&c));
    let said = String::from_utf8_lossy(&c.stderr);
    for why in ["not JSON (truncated?)", "unknown status \"weird\"", "frames = -5", "symbolic link"]
    {
        assert!(said.contains(why), "{why}: {said}");
    }
    assert!(String::from_utf8_lossy(&c.stdout).contains("4 corrupt"), "{}", text(&c));
    let csv = std::fs::read_to_string(out.join("results.csv")).expect("csv");
    assert_eq!(csv.lines().filter(|l| l.contains(",corrupt,")).count(), 4, "{csv}");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    assert_eq!(header.last(), Some(&"problem"), "{csv}");
    let frames = header.iter().position(|h| *h == "frames").expect("frames column");
    for row in csv.lines().skip(1) {
        // Nothing of a corrupt result reaches its row (the columns before `problem` hold no
        // commas here).
        assert_eq!(row.split(',').nth(frames), Some(""), "{csv}");
    }
}

/// A tiny one-case manifest: `seconds` of fly-around at 96x64, no estimator.
/// A one-case campaign of `seconds` on the host's clock: these tests stop the campaign while its
/// `hitl run` child plays, which a simulated-clock case (the default) would finish too soon.
fn one_case(dir: &Path, seconds: u32) -> PathBuf {
    write(
        dir,
        "one.toml",
        &format!(
            "[run]\nduration_s = {seconds}\ncapture_every_s = 1\narc_deg = \"420:440\"\n\
             camera_size = \"96x64\"\nperception = \"none\"\nrange_m = 5\nconfig = \"{SHARED_VM_LAB}\"\n\
             clock = \"realtime\"\n"
        ),
    )
}

fn start_campaign(m: &Path, out: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(["campaign", "run", s(m), "--out", s(out), "--jobs", "1", "--plain"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start campaign")
}

/// The pid of `parent`'s child whose command line has `word`, if one runs.
fn child_of(parent: u32, word: &str) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let stat = std::fs::read_to_string(e.path().join("stat")).ok()?;
        let ppid: u32 = stat.rsplit_once(')')?.1.split_whitespace().nth(1)?.parse().ok()?;
        let cmd = std::fs::read(e.path().join("cmdline")).ok()?;
        let has = cmd.split(|&b| b == 0).any(|a| a == word.as_bytes());
        (ppid == parent && has).then_some(pid)
    })
}

/// Whether `pid` still runs (a zombie has ended).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            s.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().next().map(String::from))
        })
        .is_some_and(|state| state != "Z" && state != "X")
}

/// Wait for `campaign`'s `hitl run` child, then a little longer (it is playing).
fn wait_for_run_child(campaign: &mut Child) -> u32 {
    let t0 = Instant::now();
    loop {
        if let Some(pid) = child_of(campaign.id(), "--record") {
            std::thread::sleep(Duration::from_secs(3));
            return pid;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "no `hitl run` child in 120 s");
        if let Ok(Some(st)) = campaign.try_wait() {
            panic!("campaign ended before its run started: {st}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn kill_9_of_a_campaign_ends_its_child_within_5_s() {
    let _turn = playing();
    let d = tempfile::tempdir().expect("tempdir");
    let m = one_case(d.path(), 30);
    let out = d.path().join("out");
    let mut campaign = start_campaign(&m, &out);
    let run = wait_for_run_child(&mut campaign);
    assert!(alive(run));
    campaign.kill().expect("kill -9");
    let _ = campaign.wait();
    let t = Instant::now();
    while alive(run) {
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "hitl run {run} outlived its campaign by 5 s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    eprintln!("hitl run ended {:?} after its campaign was killed", t.elapsed());
    // It ended in its controlled stop, as on Ctrl-C.
    let log: String = std::fs::read_dir(out.join("cases"))
        .expect("cases")
        .flatten()
        .map(|e| std::fs::read_to_string(e.path().join("run.log")).unwrap_or_default())
        .collect();
    assert!(log.contains("the operator stopped the run"), "{log}");
    // The parent-death signal may come once per dying campaign thread: one stop, never counted
    // as Ctrl-C presses (a third abandoned the stop before).
    assert_eq!(log.matches("hitl: hang-up (SIGHUP").count(), 1, "{log}");
    assert!(!log.contains("controlled stop in progress"), "{log}");
}

#[test]
fn ctrl_c_reaches_the_running_stage_and_exits_130() {
    let _turn = playing();
    let d = tempfile::tempdir().expect("tempdir");
    let m = one_case(d.path(), 30);
    let out = d.path().join("out");
    let mut campaign = start_campaign(&m, &out);
    let run = wait_for_run_child(&mut campaign);
    // SIGINT to the campaign alone (its children are in process groups of their own).
    let k = Command::new("kill").args(["-INT", &campaign.id().to_string()]).status().expect("kill");
    assert!(k.success());
    let t = Instant::now();
    let status = loop {
        if let Some(st) = campaign.try_wait().expect("wait") {
            break st;
        }
        assert!(t.elapsed() < Duration::from_secs(30), "campaign did not stop in 30 s");
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut err = String::new();
    if let Some(mut e) = campaign.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut err);
    }
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    assert!(!alive(run), "hitl run still runs");
    let dir = std::fs::read_dir(out.join("cases")).expect("cases").flatten().next().expect("case");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("result.json")).expect("result"))
            .expect("json");
    assert_eq!(r["failed_stage"], "run", "{r:#}");
    assert_eq!(r["exit_code"], 130, "a controlled stop: {r:#}");
}

#[test]
fn a_second_campaign_on_a_held_folder_is_refused_and_the_first_completes() {
    let _turn = playing();
    let d = tempfile::tempdir().expect("tempdir");
    let m = one_case(d.path(), 3);
    let out = d.path().join("out");
    let mut first = start_campaign(&m, &out);
    let _ = wait_for_run_child(&mut first);
    for extra in [&[][..], &["--index", "0"][..]] {
        let mut args = vec!["campaign", "run", s(&m), "--out", s(&out), "--plain"];
        args.extend_from_slice(extra);
        let second = hitl(&args);
        assert_eq!(second.status.code(), Some(75), "{extra:?}: {}", text(&second));
        assert!(text(&second).contains("is in use"), "{}", text(&second));
    }
    let status = first.wait().expect("first");
    let dir = std::fs::read_dir(out.join("cases")).expect("cases").flatten().next().expect("case");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("result.json")).expect("result"))
            .expect("json");
    // Untouched: played to its end (a loaded box may still trip an interlock, exit 4 in `run`;
    // never a stage cut short by a signal or a setup failure).
    match status.code() {
        Some(0) => assert_eq!(r["status"], "ok", "{r:#}"),
        Some(1) => {
            assert_eq!((&r["failed_stage"], &r["exit_code"]), (&"run".into(), &4.into()), "{r:#}")
        }
        other => panic!("first campaign: {other:?} {r:#}"),
    }
    // Once it is over the folder is free: the same command resumes (nothing left to play).
    if status.code() == Some(0) {
        let again = hitl(&["campaign", "run", s(&m), "--out", s(&out), "--plain"]);
        assert_eq!(again.status.code(), Some(0), "{}", text(&again));
        assert!(text(&again).contains("1 already done"), "{}", text(&again));
    }
}
