//! `hitl check` end to end: the binary on NPZ files written by real numpy (and by hitl), each bad
//! input getting exit 2 with a message naming the problem, unsafe motion exit 3, safe exit 0.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Writes every fixture with numpy into the folder given as argv[1].
const FIXTURES_PY: &str = r#"
import json, os, struct, sys, zipfile
import numpy as np

out = sys.argv[1]
LOOK = np.array([0.0, -0.4, 0.0, 1.4, 0.0, 1.5, 0.0])

def smooth(n=21, span=4.0, amp=0.1):
    t = np.linspace(0.0, span, n)
    bump = np.sin(np.pi * t / span) ** 2
    q = LOOK[None, :] + amp * bump[:, None] * (1.0 + np.arange(7)[None, :] / 7.0)
    return t, q

def save(name, compressed=False, **arrays):
    (np.savez_compressed if compressed else np.savez)(os.path.join(out, name), **arrays)

t, q = smooth()
capture = np.zeros(len(t), dtype=bool); capture[::5] = True
light = np.linspace(0.2, 1.0, len(t)).astype(np.float32)
meta = np.array(json.dumps({"preset": "test", "scale": 1.0}))
save("safe.npz", qpos=q, t=t, capture=capture, light=light, meta=meta)
save("safe_f32_fortran.npz", compressed=True, qpos=np.asfortranarray(q.astype(np.float32)), t=t,
     extra_key=np.arange(3.0))

bad = q.copy(); bad[3, 2] = np.nan; save("nan.npz", qpos=bad, t=t)
bt = t.copy(); bt[5] = np.inf; save("inf_t.npz", qpos=q, t=bt)
save("width6.npz", qpos=q[:, :6], t=t)
bt = t.copy(); bt[2] = bt[1]; save("t_flat.npz", qpos=q, t=bt)
save("one.npz", qpos=q[:1], t=t[:1])
save("no_qpos.npz", t=t)
save("no_t.npz", qpos=q)
save("short_capture.npz", qpos=q, t=t, capture=capture[:-1])
bl = light.copy(); bl[4] = 1.5; save("light_high.npz", qpos=q, t=t, light=bl)
save("int_qpos.npz", qpos=np.round(q * 1000).astype(np.int64), t=t)
save("complex_t.npz", qpos=q, t=t.astype(np.complex128))
np.savez(os.path.join(out, "object.npz"), qpos=np.array([list(r) for r in q] + [None], dtype=object)[:-1], t=t)
np.savez(os.path.join(out, "object_meta.npz"), qpos=q, t=t, meta=np.array({"a": 1}, dtype=object))

# A header declaring 10^12 waypoints over 16 bytes of data.
header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 7), }"
header += " " * ((64 - (10 + len(header) + 1) % 64) % 64) + "\n"
npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + b"\0" * 16
with zipfile.ZipFile(os.path.join(out, "huge.npz"), "w") as z:
    z.writestr("qpos.npy", npy)
    z.writestr("t.npy", b"")

data = open(os.path.join(out, "safe.npz"), "rb").read()
open(os.path.join(out, "truncated.npz"), "wb").write(data[: len(data) // 2])
open(os.path.join(out, "not_zip.npz"), "w").write("qpos,t\n0,0\n")

# Joint 4 held at -0.10 rad (arm upright, joint 1 sweeping 0.1 rad): inside the first xArm7s'
# table less the 0.05 rad margin (-0.142), outside the current arms' (-0.055).
j4 = np.tile([0.0, -0.4, 0.0, -0.10, 0.0, 1.0, 0.0], (21, 1)); j4[:, 0] = 0.1 * np.sin(np.pi * t / 4.0) ** 2
save("joint4_minus_0.10.npz", qpos=j4, t=t)
# Joint 4 pushed below its lower limit (-0.19 rad) in the middle.
bq = q.copy(); bq[8:13, 3] = -0.3; save("joint4_low.npz", qpos=bq, t=t)
# One rest-to-rest move of joint 1 by 0.5 rad in 1 s: 0.94 rad/s peak, inside the velocity limit,
# but 0.019 rad per tick at 50 Hz (limit 0.01).
q2 = np.stack([LOOK, LOOK]); q2[1, 0] += 0.5
save("fast_step.npz", qpos=q2, t=np.array([0.0, 1.0]))

# Files from another pipeline: sampled at 100 Hz from a slow sine (0.1 rad, 0.2 Hz) of joint 1,
# starting and ending in the middle of the motion.
def sine(span, phase):
    ts = np.arange(int(round(span * 100)) + 1) / 100.0
    qs = np.tile(LOOK, (len(ts), 1)); qs[:, 0] += 0.1 * np.sin(2 * np.pi * 0.2 * ts + phase)
    return ts, qs
ts, qs = sine(6.0, 0.0)
save("moving_sine.npz", qpos=qs, t=ts)
save("moving_sine_no_t.npz", qpos=qs)
# From crest to trough: at rest at both ends, but accelerating (0.158 rad/s^2).
tc, qc = sine(2.5, np.pi / 2)
save("crest_to_trough.npz", qpos=qc, t=tc)
# Too fast for the lab: joint 7 swings 0.8 rad and back in 1 s (2.51 rad/s, 15.8 rad/s^2,
# 99 rad/s^3 against limits of 1, 4 and 60).
tf = np.linspace(0.0, 1.0, 101)
qf = np.tile(LOOK, (len(tf), 1)); qf[:, 6] += 0.8 * np.sin(np.pi * tf) ** 2
save("too_fast.npz", qpos=qf, t=tf)
# Ends at 0.9 rad/s and still accelerating at 3.5 rad/s^2 (joint 7): inside every limit, but no
# jerk-limited stop from there stays under 1 rad/s, so the lead-out breaks the velocity limit.
qh = np.tile(LOOK, (len(tf), 1)); qh[:, 6] += -0.26667 * tf ** 3 + 0.425 * tf ** 4
save("hot_end.npz", qpos=qh, t=tf)
# 2 s of slow motion with a capture at every waypoint: 25 Hz (every 40 ms) and 10 Hz (100 ms).
for name, dt in (("captures_25hz.npz", 0.04), ("captures_10hz.npz", 0.1)):
    tk = np.arange(int(round(2.0 / dt)) + 1) * dt
    qk = np.tile(LOOK, (len(tk), 1)); qk[:, 0] += 0.05 * np.sin(np.pi * tk / 2.0) ** 2
    save(name, qpos=qk, t=tk, capture=np.ones(len(tk), dtype=bool))
"#;

fn python() -> PathBuf {
    let p = PathBuf::from(env!("HITL_VENV_PYTHON"));
    assert!(p.exists(), "{} is missing: run make setup", p.display());
    p
}

/// The fixture folder, written once per test binary.
fn fixtures() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("hitl-check-cli-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let out = Command::new(python())
            .arg("-c")
            .arg(FIXTURES_PY)
            .arg(&dir)
            .output()
            .expect("run the venv python (run make setup)");
        assert!(out.status.success(), "fixtures: {}", String::from_utf8_lossy(&out.stderr));
        dir
    })
}

struct Outcome {
    code: i32,
    text: String,
}

fn check(file: &str, extra: &[&str]) -> Outcome {
    let path = fixtures().join(file);
    let out = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .arg("check")
        .arg(&path)
        .args(extra)
        .output()
        .expect("run hitl");
    let text =
        format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(!text.contains("panicked"), "hitl panicked on {file}: {text}");
    Outcome { code: out.status.code().unwrap_or(-1), text }
}

/// Exit code `code` and every one of `words` in the output.
fn expect(file: &str, extra: &[&str], code: i32, words: &[&str]) {
    let o = check(file, extra);
    assert_eq!(o.code, code, "{file} {extra:?}: {}", o.text);
    for w in words {
        assert!(o.text.contains(w), "{file}: expected '{w}' in: {}", o.text);
    }
}

#[test]
fn a_safe_trajectory_passes_with_its_report() {
    expect(
        "safe.npz",
        &[],
        0,
        &["SAFE", "21 waypoints", "4.000 s", "1001 ticks at 250 Hz", "5 capture(s)", "floor"],
    );
    // float32, Fortran order, compressed, an unknown key warned about.
    expect("safe_f32_fortran.npz", &[], 0, &["SAFE", "unknown key 'extra_key.npy' ignored"]);
}

#[test]
fn a_rate_the_run_would_refuse_is_warned_about() {
    expect("safe.npz", &["--rate", "300"], 0, &["SAFE", "--rate 300 Hz is above the 250 Hz"]);
    let o = check("safe.npz", &["--rate", "250"]);
    assert!(!o.text.contains("warning: --rate"), "{}", o.text);
}

#[test]
fn json_report_is_one_object() {
    let o = check("safe.npz", &["--json", "--rate", "500", "--speed-scale", "0.5"]);
    assert_eq!(o.code, 0, "{}", o.text);
    let v: serde_json::Value = serde_json::from_str(o.text.trim()).expect("one JSON object");
    assert_eq!(v["safe"], true);
    assert_eq!(v["rate_hz"], 500.0);
    assert_eq!(v["rate_refused_by_run"], true, "500 Hz is above what a box receives");
    assert_eq!(v["ticks"], 4001);
    assert_eq!(v["joints"].as_array().map(Vec::len), Some(7));
    assert_eq!(v["clearances"].as_array().map(Vec::len), Some(10));
    let o = check("nan.npz", &["--json"]);
    assert_eq!(o.code, 2);
    let first = o.text.lines().next().unwrap_or_default();
    let v: serde_json::Value = serde_json::from_str(first).expect("error object");
    assert!(v["error"].as_str().unwrap_or_default().contains("qpos"), "{v}");
}

#[test]
fn non_finite_values_name_key_and_waypoint() {
    expect("nan.npz", &[], 2, &["'qpos'", "waypoint 3", "joint 3", "not finite"]);
    expect("inf_t.npz", &[], 2, &["'t'", "waypoint 5", "not finite"]);
}

#[test]
fn shape_and_count_problems_are_named() {
    expect("width6.npz", &[], 2, &["'qpos'", "shape [21, 6]", "(N, 7)"]);
    expect("one.npz", &[], 2, &["'qpos'", "1 waypoint", "at least 2"]);
    expect("no_qpos.npz", &[], 2, &["'qpos' is missing"]);
    expect("no_t.npz", &[], 2, &["'t' is missing"]);
    expect("short_capture.npz", &[], 2, &["'capture'", "20 waypoints", "'qpos' has 21"]);
}

#[test]
fn time_must_increase_strictly() {
    expect("t_flat.npz", &[], 2, &["'t'", "waypoint 2", "increase strictly"]);
}

#[test]
fn light_outside_unit_range_is_refused() {
    expect("light_high.npz", &[], 2, &["'light'", "waypoint 4", "outside [0, 1]"]);
}

#[test]
fn refused_dtypes_are_named() {
    expect("int_qpos.npz", &[], 2, &["'qpos'", "integer"]);
    expect("complex_t.npz", &[], 2, &["'t'", "complex"]);
    expect("object.npz", &[], 2, &["'qpos'", "pickled"]);
    expect("object_meta.npz", &[], 2, &["'meta'", "pickled"]);
}

#[test]
fn damaged_files_are_refused() {
    expect("huge.npz", &[], 2, &["'qpos'", "1000000000000", "declares shape"]);
    expect("truncated.npz", &[], 2, &["truncated"]);
    expect("not_zip.npz", &[], 2, &["not an NPZ file"]);
    expect("does_not_exist.npz", &[], 2, &["cannot read", "does_not_exist.npz"]);
}

#[test]
fn a_joint_beyond_its_limit_is_unsafe() {
    expect("joint4_low.npz", &[], 3, &["UNSAFE", "joint 4", "allowed range"]);
}

#[test]
fn the_labs_joint_table_decides_joint_4_at_minus_0_10() {
    // Current xArm7s (the default table) stop joint 4 at -0.10472 rad: with the 0.05 rad margin
    // -0.10 is refused, naming the joint and the table.
    expect(
        "joint4_minus_0.10.npz",
        &[],
        3,
        &["UNSAFE", "joint 4", "xarm7-current", "table xarm7-current"],
    );
    let o = check("joint4_minus_0.10.npz", &["--json"]);
    let v: serde_json::Value = serde_json::from_str(o.text.trim()).expect("one JSON object");
    assert_eq!(v["joint_table"], "xarm7-current");
    assert_eq!(v["violations"].as_array().map(Vec::len), Some(1), "{v}");
    assert_eq!(v["violations"][0]["joint"], 4);
    // The first arms' table allows it.
    let cfg = fixtures().join("legacy.toml");
    std::fs::write(&cfg, "[arm]\njoint_table = \"xarm7-legacy\"\n").expect("write");
    let cfg = cfg.display().to_string();
    expect("joint4_minus_0.10.npz", &["--config", &cfg], 0, &["SAFE", "table xarm7-legacy"]);
    // A name that is no table is bad input.
    let bad = fixtures().join("no_table.toml");
    std::fs::write(&bad, "[arm]\njoint_table = \"xarm6\"\n").expect("write");
    let bad = bad.display().to_string();
    expect("joint4_minus_0.10.npz", &["--config", &bad], 2, &["xarm7-current", "xarm7-legacy"]);
}

#[test]
fn a_tcp_faster_than_the_lab_allows_is_unsafe() {
    let cfg = fixtures().join("slow_tcp.toml");
    std::fs::write(&cfg, "[limits]\ntcp_speed_m_s = 0.01\n").expect("write");
    let cfg = cfg.display().to_string();
    expect("safe.npz", &["--config", &cfg], 3, &["UNSAFE", "TCP linear speed", "error 60"]);
    let o = check("safe.npz", &["--json"]);
    let v: serde_json::Value = serde_json::from_str(o.text.trim()).expect("one JSON object");
    let peak = v["tcp_speed"]["peak_m_s"].as_f64().expect("peak");
    assert!(peak > 0.01 && peak < 1.0, "{v}");
    assert_eq!(v["tcp_speed"]["limit_m_s"], 1.0);
}

#[test]
fn a_tcp_speed_refusal_proposes_a_speed_scale_that_passes() {
    let cfg = fixtures().join("slowish_tcp.toml");
    std::fs::write(&cfg, "[limits]\ntcp_speed_m_s = 0.02\n").expect("write");
    let cfg = cfg.display().to_string();
    let o = check("safe.npz", &["--config", &cfg]);
    assert_eq!(o.code, 3, "{}", o.text);
    let scale = remedy(&o.text).to_string();
    expect("safe.npz", &["--config", &cfg, "--speed-scale", &scale], 0, &["SAFE"]);
}

#[test]
fn captures_faster_than_half_the_orbbecs_frame_rate_are_refused_by_check_and_run() {
    // Without --camera, no camera rule: the 25 Hz file is SAFE.
    expect("captures_25hz.npz", &[], 0, &["SAFE"]);
    let o = check("captures_25hz.npz", &["--camera", "orbbec"]);
    assert_eq!(o.code, 3, "{}", o.text);
    for w in ["25.0 Hz", "15.0 Hz", "30 fps", "capture less often"] {
        assert!(o.text.contains(w), "{w}: {}", o.text);
    }
    // 15/25 = 0.6 by the scaling law; captures fall on whole ticks, so a little less passes.
    let s = remedy(&o.text);
    let scale = s.to_string();
    assert!((0.55..=0.6).contains(&s), "{s}");
    expect("captures_25hz.npz", &["--camera", "orbbec", "--speed-scale", &scale], 0, &["SAFE"]);
    expect("captures_10hz.npz", &["--camera", "orbbec"], 0, &["SAFE", "capture rate"]);
    // `hitl run` refuses it with exit 3 before the camera is opened: no camera is attached
    // here, so opening it would have been exit 5.
    let file = fixtures().join("captures_25hz.npz");
    let out = Command::new(env!("CARGO_BIN_EXE_hitl"))
        .arg("run")
        .arg(&file)
        .args(["--camera", "orbbec:software", "--light", "none", "--plain"])
        .stdin(std::process::Stdio::null())
        .output()
        .expect("run hitl");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(err.contains("25.0 Hz") && err.contains("nothing moved"), "{err}");
}

#[test]
fn a_step_too_large_for_the_rate_is_unsafe() {
    expect("fast_step.npz", &["--rate", "50"], 3, &["UNSAFE", "joint 1 step", "50 Hz"]);
    // The same motion at 250 Hz steps 4 mrad per tick.
    expect("fast_step.npz", &[], 0, &["SAFE"]);
}

#[test]
fn bad_flags_and_config_are_bad_input() {
    expect("safe.npz", &["--rate", "20"], 2, &["50-1000 Hz"]);
    expect("safe.npz", &["--speed-scale", "0"], 2, &["speed scale"]);
    expect("safe.npz", &["--speed-scale", "fast"], 2, &["speed-scale"]);
    let cfg = fixtures().join("bad.toml");
    std::fs::write(&cfg, "[limits]\nvelocity_rad_s = [9.0, 1, 1, 1, 1, 1, 1]\n").expect("write");
    let cfg = cfg.display().to_string();
    expect("safe.npz", &["--config", &cfg], 2, &["velocity_rad_s[0]"]);
}

#[test]
fn a_config_changes_the_verdict() {
    // A lab with a tighter velocity limit refuses the same file.
    let cfg = fixtures().join("slow.toml");
    std::fs::write(&cfg, "[limits]\nvelocity_rad_s = [0.05, 1, 1, 1, 1, 1, 1]\n").expect("write");
    let cfg = cfg.display().to_string();
    expect("safe.npz", &["--config", &cfg], 3, &["joint 1 velocity", "exceeds the limit 0.05"]);
}

#[test]
fn a_file_hitl_writes_checks_like_numpys() {
    let numpy = hitl_trajectories::npz::load(&fixtures().join("safe.npz")).expect("load");
    let ours = fixtures().join("ours.npz");
    hitl_trajectories::npz::save(&ours, &numpy.trajectory, true).expect("save");
    expect("ours.npz", &[], 0, &["SAFE", "21 waypoints"]);
}

#[test]
fn a_file_that_starts_and_ends_moving_plays_with_a_lead_in_and_a_lead_out() {
    // Today's rest-to-rest ends would put a jerk of ~10^4 rad/s^3 at the first and last ticks.
    expect(
        "moving_sine.npz",
        &[],
        0,
        &[
            "SAFE",
            "601 waypoints",
            "phases: lead-in",
            "playback of the file's 1501 ticks",
            "lead-out",
        ],
    );
    // At rest but accelerating at both ends: ramps too.
    expect("crest_to_trough.npz", &[], 0, &["SAFE", "phases: lead-in", "lead-out"]);
    let o = check("moving_sine.npz", &["--json"]);
    assert_eq!(o.code, 0, "{}", o.text);
    let v: serde_json::Value = serde_json::from_str(o.text.trim()).expect("one JSON object");
    let (lead_in, lead_out) = (v["lead_in_ticks"].as_u64(), v["lead_out_ticks"].as_u64());
    assert!(lead_in.is_some_and(|n| n > 0) && lead_out.is_some_and(|n| n > 0), "{v}");
    assert_eq!(v["ticks"].as_u64(), Some(1501 + lead_in.unwrap_or(0) + lead_out.unwrap_or(0)));
    // Every joint inside its limits over the ramps as well (the report's peaks cover them).
    for j in v["joints"].as_array().expect("joints") {
        assert!(j["peak_jerk"].as_f64() < j["jerk_limit"].as_f64(), "{j}");
    }
    // A file at rest at both ends has no ramps.
    let o = check("safe.npz", &[]);
    assert!(!o.text.contains("lead-in"), "{}", o.text);
}

#[test]
fn a_file_without_t_needs_its_waypoint_rate() {
    expect("moving_sine_no_t.npz", &[], 2, &["'t' is missing", "--waypoint-rate HZ"]);
    let o = check("moving_sine_no_t.npz", &["--json"]);
    assert_eq!(o.code, 2);
    assert!(o.text.contains("--waypoint-rate"), "{}", o.text);
    expect("moving_sine_no_t.npz", &["--waypoint-rate", "100"], 0, &["SAFE", "601 waypoints"]);
    // The same file with its times checks the same.
    let with_t = check("moving_sine.npz", &["--json"]);
    let without = check("moving_sine_no_t.npz", &["--json", "--waypoint-rate", "100"]);
    let (a, b): (serde_json::Value, serde_json::Value) = (
        serde_json::from_str(with_t.text.trim()).expect("json"),
        serde_json::from_str(without.text.trim()).expect("json"),
    );
    assert_eq!(a["joints"], b["joints"]);
    // A rate for a file with its own t, or a rate that is no rate, is refused.
    expect("moving_sine.npz", &["--waypoint-rate", "100"], 2, &["has its own key 't'"]);
    expect("moving_sine_no_t.npz", &["--waypoint-rate", "0"], 2, &["--waypoint-rate 0 Hz"]);
    expect("moving_sine_no_t.npz", &["--waypoint-rate", "nan"], 2, &["--waypoint-rate NaN Hz"]);
}

/// The `--speed-scale` value `hitl check` offers as its remedy.
fn remedy(text: &str) -> f64 {
    let after = text.split("remedy: --speed-scale ").nth(1).unwrap_or_else(|| panic!("{text}"));
    after.split_whitespace().next().and_then(|w| w.parse().ok()).expect("a number")
}

#[test]
fn a_file_too_fast_for_the_lab_gets_the_speed_scale_that_passes() {
    let o = check("too_fast.npz", &[]);
    assert_eq!(o.code, 3, "{}", o.text);
    assert!(o.text.contains("joint 7 velocity"), "{}", o.text);
    let s = remedy(&o.text);
    // Velocity binds: the limit over the file's peak, 1 / (0.4 * 2 pi) = 0.39789 (acceleration
    // would allow 0.50, jerk 0.85), to 4 digits; the ticks sample just below the peak.
    let bound = 1.0 / (0.4 * 2.0 * std::f64::consts::PI);
    assert!((s - bound).abs() < 3e-4, "{s} vs {bound}");
    let o = check("too_fast.npz", &["--json"]);
    let j: serde_json::Value = serde_json::from_str(o.text.trim()).expect("json");
    // The printed value passes; 1 % faster does not.
    let v = s.to_string();
    expect("too_fast.npz", &["--speed-scale", &v], 0, &["SAFE"]);
    let faster = format!("{:.4}", s * 1.01);
    expect("too_fast.npz", &["--speed-scale", &faster], 3, &["joint 7 velocity"]);
    // The JSON report carries it; a safe file or one refused for clearance gets none.
    assert_eq!(j["speed_scale_to_pass"].as_f64(), Some(s));
    let o = check("safe.npz", &["--json"]);
    let j: serde_json::Value = serde_json::from_str(o.text.trim()).expect("json");
    assert!(j["speed_scale_to_pass"].is_null(), "{j}");
    let o = check("joint4_low.npz", &[]);
    assert!(!o.text.contains("remedy"), "{}", o.text);
}

#[test]
fn a_lead_out_over_the_limit_is_refused_and_slowing_down_cures_it() {
    let o = check("hot_end.npz", &[]);
    assert_eq!(o.code, 3, "{}", o.text);
    assert!(o.text.contains("no lead-in (the file starts at rest)"), "{}", o.text);
    assert!(
        o.text.contains("joint 7 velocity") && o.text.contains("in the lead-out"),
        "{}",
        o.text
    );
    let s = remedy(&o.text);
    assert!(s > 0.9 && s < 1.0, "{s}");
    expect("hot_end.npz", &["--speed-scale", &s.to_string()], 0, &["SAFE"]);
}
