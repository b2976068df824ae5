//! A lab configuration with a NaN, an infinity or a value out of its documented range
//! (docs/lab-config.md) is exit 2 naming the key, from every command that reads one, before any
//! device opens: nothing is planned, played, recorded or written.

mod common;

use common::hitl;
use std::path::Path;

const PRESET: &str =
    concat!(env!("CARGO_MANIFEST_DIR"), "/trajectories/presets/flyaround-50m-25s.npz");

/// Each bad lab and the words its refusal must contain.
const BAD_LABS: [(&str, &str); 4] = [
    ("[target]\nrpy_deg = [nan, 0, 0]\n", "target.rpy_deg[0] = NaN must be a finite number"),
    ("[camera]\nrpy_deg = [0, 0, nan]\n", "camera.rpy_deg[2] = NaN must be a finite number"),
    ("[camera.body]\ndepth_m = inf\n", "camera.body.depth_m = inf must be a finite number"),
    ("[interlocks]\nreport_timeout_ms = 60000\n", "interlocks.report_timeout_ms = 60000"),
];

fn write_lab(dir: &Path, i: usize, text: &str) -> String {
    let p = dir.join(format!("lab{i}.toml"));
    std::fs::write(&p, text).expect("lab");
    p.to_str().expect("utf-8").to_string()
}

fn assert_refused(out: &std::process::Output, words: &str, file: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{words}: {err}");
    assert!(err.contains(words), "the refusal names the key: {err}");
    assert!(err.contains(file), "the refusal names the file {file}: {err}");
    assert!(!err.contains("approach"), "nothing may start moving: {err}");
}

#[test]
fn check_plan_run_and_stub_refuse_a_bad_lab_before_anything_opens() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (i, (text, words)) in BAD_LABS.iter().enumerate() {
        let lab = write_lab(dir.path(), i, text);
        let out = hitl(&["check", PRESET, "--config", &lab]);
        assert_refused(&out, words, &lab);
        assert!(!String::from_utf8_lossy(&out.stdout).contains("SAFE"));

        let npz = dir.path().join(format!("plan{i}.npz"));
        let out = hitl(&[
            "plan",
            "--preset",
            "flyaround",
            "--config",
            &lab,
            "--out",
            npz.to_str().expect("utf-8"),
        ]);
        assert_refused(&out, words, &lab);
        assert!(!npz.exists(), "plan wrote {} from a bad lab", npz.display());

        let rec = dir.path().join(format!("run{i}.mcap"));
        let rec = rec.to_str().expect("utf-8");
        let out = hitl(&["run", PRESET, "--plain", "--config", &lab, "--record", rec]);
        assert_refused(&out, words, &lab);
        assert!(!Path::new(rec).exists(), "run recorded from a bad lab");

        // The embedded stub's hidden lab is held to the same rules.
        let out = hitl(&["run", PRESET, "--plain", "--stub-config", &lab, "--record", rec]);
        assert_refused(&out, words, &lab);
        assert!(!Path::new(rec).exists(), "run recorded from a bad --stub-config");

        // The standalone stub refuses it before it binds a port.
        let out = hitl(&["stub", "--config", &lab, "--cmd-port", "0", "--report-port", "40003"]);
        assert_refused(&out, words, &lab);
    }
}

#[test]
fn calibrate_refuses_a_bad_lab_or_stub_lab_before_anything_moves() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_toml = dir.path().join("calibrated.toml");
    let out_arg = out_toml.to_str().expect("utf-8");
    for (i, (text, words)) in BAD_LABS.iter().enumerate() {
        let lab = write_lab(dir.path(), i, text);
        let out = hitl(&["calibrate", "--config", &lab, "--out", out_arg]);
        assert_refused(&out, words, &lab);
        let out = hitl(&["calibrate", "--stub-config", &lab, "--out", out_arg]);
        assert_refused(&out, words, &lab);
        assert!(!out_toml.exists(), "calibrate wrote {out_arg} from a bad lab");
    }
}
