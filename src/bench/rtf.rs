//! `hitl bench rtf`: the simulated clock's real-time factor on a campaign case
//! (docs/sim-clock.md).
//!
//! The case is issue 28's: a fly-around at 10 m lasting 30 s with a capture every 0.2 s (151
//! captures), the WFOV camera, the simulated light, ICP on the ground-truth mesh, recorded, on
//! `--clock sim`. It is played as `hitl campaign run` plays a case (the same `hitl plan` and
//! `hitl run` arguments, as child processes of this binary), once per image size. Per size: the
//! simulated seconds (approach and retreat included), the loop's host seconds and factor (the
//! run's own summary), the whole `hitl run` process's host seconds and factor (start-up, scene,
//! renderer and the recorder's close included), where the loop's host time went, and the CPU
//! seconds the process used with the host's 1-minute load average before and after: on a
//! shared machine the factor follows the load, the CPU time much less.

use crate::cli::campaign::{manifest, run as case_run};
use serde_json::{json, Value};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

/// The fly-around's length, simulated seconds (approach and retreat come on top).
pub const DURATION_S: f64 = 30.0;
/// Seconds between captures: 151 captures over [`DURATION_S`].
pub const CAPTURE_EVERY_S: f64 = 0.2;

/// What `hitl bench rtf` plays.
#[derive(Debug, Clone)]
pub struct RtfOptions {
    /// Image sizes, one case each.
    pub sizes: Vec<(u32, u32)>,
    /// The fly-around's nearest range, metres.
    pub range_m: f64,
    /// The target (built-in name or mesh file).
    pub target: String,
}

/// Play the case at each size under `dir` (its recordings removed as each case ends).
pub fn run(o: &RtfOptions, exe: &Path, dir: &Path) -> Value {
    let sizes: Vec<Value> = o
        .sizes
        .iter()
        .map(|&(w, h)| one_size(o, w, h, exe, dir).unwrap_or_else(|e| json!({ "error": e })))
        .collect();
    json!({
        "bench": "rtf",
        "case": {
            "preset": "flyaround", "range_m": o.range_m, "duration_s": DURATION_S,
            "capture_every_s": CAPTURE_EVERY_S, "camera_preset": "wfov", "perception": "icp",
            "target": o.target, "clock": "sim",
        },
        "sizes": sizes,
    })
}

/// The case's manifest at one size.
fn manifest_text(o: &RtfOptions, w: u32, h: u32) -> String {
    format!(
        "[run]\npreset = \"flyaround\"\nrange_m = {}\nduration_s = {DURATION_S}\n\
         capture_every_s = {CAPTURE_EVERY_S}\ncamera_preset = \"wfov\"\ncamera_size = \"{w}x{h}\"\n\
         perception = \"icp\"\ntarget = {:?}\nclock = \"sim\"\n",
        o.range_m, o.target
    )
}

fn one_size(o: &RtfOptions, w: u32, h: u32, exe: &Path, dir: &Path) -> Result<Value, String> {
    let m =
        manifest::parse(&manifest_text(o, w, h), dir, "bench-rtf").map_err(|e| e.to_string())?;
    let case = m.cases().next().ok_or("the bench's manifest has no case")?;
    let case_dir = dir.join(format!("{w}x{h}"));
    std::fs::create_dir_all(&case_dir).map_err(|e| format!("{}: {e}", case_dir.display()))?;
    let plan = case_dir.join("plan.npz");
    let (plan_args, _) = case_run::plan_args(&case, &plan)?;
    let planned = child(exe, &plan_args)?;
    if !planned.0.success() {
        return Err(format!("hitl plan failed: {}", tail(&planned.1)));
    }
    let record = case_dir.join("run.mcap");
    let (load_before, cpu_before) = (load_avg(), children_cpu_s());
    let t0 = Instant::now();
    let (status, text) = child(exe, &case_run::run_args(&case, &plan, &record))?;
    let process_s = t0.elapsed().as_secs_f64();
    let cpu_s = children_cpu_s().zip(cpu_before).map(|(after, before)| after - before);
    let _ = std::fs::remove_dir_all(&case_dir);
    let (sim_s, loop_s, loop_factor) = summary(&text)
        .ok_or_else(|| format!("hitl run printed no simulated-clock summary: {}", tail(&text)))?;
    let captures = text
        .lines()
        .find_map(|l| l.strip_prefix("captures ")?.split(',').next()?.trim().parse::<u64>().ok());
    let lockstep = text.lines().find(|l| l.starts_with("lockstep host time:"));
    Ok(json!({
        "size": format!("{w}x{h}"),
        "exit_code": status.code(),
        "captures": captures,
        "simulated_s": sim_s,
        "loop_host_s": loop_s,
        "loop_real_time_factor": loop_factor,
        "process_host_s": process_s,
        "process_real_time_factor": sim_s / process_s,
        "process_cpu_s": cpu_s,
        "load_avg_1min": [load_before, load_avg()],
        "lockstep": lockstep,
    }))
}

/// Runs `exe ARGS` with no stdin; its exit status and what it printed.
fn child(exe: &Path, args: &[String]) -> Result<(std::process::ExitStatus, String), String> {
    let out = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run {}: {e}", exe.display()))?;
    let text =
        format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    Ok((out.status, text))
}

/// The host's 1-minute load average (`/proc/loadavg`).
fn load_avg() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg").ok()?.split_whitespace().next()?.parse().ok()
}

/// CPU seconds (user + system) of this process's waited-for children (`/proc/self/stat`'s
/// cutime and cstime, in the kernel's fixed 100 ticks per second).
fn children_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name's closing parenthesis start at field 3 (state).
    let rest: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = |field: usize| rest.get(field - 3)?.parse::<u64>().ok();
    Some((ticks(16)? + ticks(17)?) as f64 / 100.0)
}

fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(5)..].join("\n")
}

/// `simulated clock: S s simulated in W s (Fx real time)`: S, W and F.
fn summary(text: &str) -> Option<(f64, f64, f64)> {
    let line = text.lines().rev().find_map(|l| l.strip_prefix("simulated clock:"))?;
    let t: Vec<&str> = line.split_whitespace().collect();
    let num = |i: usize, strip: &[char]| -> Option<f64> {
        t.get(i)?.trim_matches(|c| strip.contains(&c)).parse().ok()
    };
    Some((num(0, &[])?, num(4, &[])?, num(6, &['(', 'x'])?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_runs_simulated_clock_summary() {
        let text = "completed\nsimulated clock: 53.300 s simulated in 10.661 s (5.00x real time)\n\
                    lockstep host time: 1 s\n";
        assert_eq!(summary(text), Some((53.3, 10.661, 5.0)));
        assert_eq!(summary("completed\n"), None);
    }

    #[test]
    fn reads_the_childrens_cpu_time_and_the_load() {
        let before = children_cpu_s().expect("/proc/self/stat");
        let spin = "i=0; while [ $i -lt 100000 ]; do i=$((i+1)); done";
        let ok = Command::new("sh").args(["-c", spin]).status().expect("sh");
        assert!(ok.success());
        let after = children_cpu_s().expect("/proc/self/stat");
        assert!(after > before, "{before} -> {after}");
        assert!(load_avg().is_some_and(|l| l >= 0.0));
    }

    #[test]
    fn the_case_is_a_valid_campaign_case_of_151_captures() {
        let o = RtfOptions { sizes: vec![], range_m: 10.0, target: "asymmetric".into() };
        let m = manifest::parse(&manifest_text(&o, 320, 256), Path::new("/m"), "b").expect("ok");
        let c = m.cases().next().expect("a case");
        assert_eq!(c.text("camera_size"), Some("320x256"));
        assert_eq!(c.text("clock"), Some("sim"));
        assert_eq!((DURATION_S / CAPTURE_EVERY_S).round() as u64 + 1, 151);
    }
}
