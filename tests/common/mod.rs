//! Helpers shared by the end-to-end tests: running the `hitl` binary, and the lab they play in.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::Path;
use std::process::{Command, Output, Stdio};

/// What a finished `hitl` printed, stdout then stderr (for assertion messages and summaries).
pub fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// The stub's lab for the closed-loop tests: the target 5 mm (lab) from where the shared-VM lab
/// puts it (`--stub-config`), so the controller's belief and the truth differ.
pub const STUB_5MM_OFF: &str =
    concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/target-5mm-off-lab.toml");

/// Runs `hitl ARGS...` with no stdin and returns what it printed and its exit status.
pub fn hitl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run hitl")
}

/// The default lab with a watchdog and deviation limit a shared VM's steal time cannot trip by
/// itself (the file says why). Tests about those interlocks keep the defaults.
pub const SHARED_VM_LAB: &str =
    concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/shared-vm-lab.toml");

/// The default lab with 400 ms silence limits, for the tests that silence the arm: what they
/// inject, not the host's scheduling, trips (the file says why).
pub const SILENCE_LAB: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/silence-lab.toml");

/// `hitl run` flags of the capture tests: the simulated WFOV camera at 320x256, the simulated
/// light, plain progress and the shared-VM lab (these tests are about captures and estimates;
/// the interlocks a shared VM can trip have tests of their own).
pub const SIM_CAPTURE_RUN: [&str; 11] = [
    "--camera",
    "sim",
    "--camera-preset",
    "wfov",
    "--camera-size",
    "320x256",
    "--light",
    "sim",
    "--plain",
    "--config",
    SHARED_VM_LAB,
];

/// `hitl run` on the simulated clock (docs/sim-clock.md): the run plays in lockstep with the
/// embedded stub as fast as the machine allows, and what it records does not depend on the
/// machine's load. For the end-to-end tests that do not test timing (lateness, overruns, stalls)
/// or a real device peer: those stay on the host's clock.
pub const SIM_CLOCK: [&str; 2] = ["--clock", "sim"];

/// Plans a 20 s fly-around at `range_m` with a capture every `capture_every` waypoints into
/// `out`, and checks `hitl plan` succeeded.
pub fn plan_flyaround(out: &Path, range_m: &str, capture_every: &str) {
    plan_flyaround_arc(out, range_m, capture_every, None);
}

/// [`plan_flyaround`] over the arc of argument of latitude `arc` (`hitl plan --arc FROM:TO`)
/// instead of the preset's.
pub fn plan_flyaround_arc(out: &Path, range_m: &str, capture_every: &str, arc: Option<&str>) {
    let out = out.to_str().expect("utf-8 path");
    let mut args = vec![
        "plan",
        "--preset",
        "flyaround",
        "--range-m",
        range_m,
        "--duration-s",
        "20",
        "--capture-every",
        capture_every,
        "--out",
        out,
    ];
    if let Some(arc) = arc {
        args.extend(["--arc", arc]);
    }
    let plan = hitl(&args);
    assert_eq!(plan.status.code(), Some(0), "{}", String::from_utf8_lossy(&plan.stderr));
}

/// A number from a JSON object, or a panic naming the key.
pub fn num(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("no number `{key}` in {v}"))
}
