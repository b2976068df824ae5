//! `hitl bench loop`: how punctually the real-time thread wakes, with and without load, side by
//! side with the machine's floor, `cyclictest` (Debian rt-tests: SCHED_FIFO, mlockall,
//! clock_nanosleep to absolute deadlines, the same period, priority and load), and with a plain
//! Python loop that sleeps for the period (what the official SDK's examples do). The ratios
//! hitl/cyclictest at p50 and p99 say how far the controller's loop is from what the machine can
//! do (the goal: within 1.5x).
//!
//! The measured loop is the controller's own: [`Periodic`] against absolute deadlines, the OS
//! settings of [`crate::rt::os`], and a tick-sized piece of work (a slot read, a servo_j encode,
//! telemetry pushes). Load is one busy thread per core doing recorder-like work (compression-sized
//! memory traffic) and perception-like work (floating-point loops).

use super::load::under_load;
use crate::rt::{os, Pace, Periodic, RtOptions};
use crossbeam::queue::ArrayQueue;
use hitl_hal::DOF;
use serde_json::{json, Value};
use std::process::Command;
use std::time::Duration;

/// What to measure.
#[derive(Debug, Clone)]
pub struct LoopBenchOptions {
    pub seconds: f64,
    pub rate_hz: f64,
    pub load: bool,
    pub rt: RtOptions,
    /// Python interpreter for the side-by-side loop (None: skip it).
    pub python: Option<String>,
}

/// Percentiles of a sample, microseconds.
fn percentiles_us(mut ns: Vec<u64>) -> Value {
    if ns.is_empty() {
        return json!(null);
    }
    ns.sort_unstable();
    let at = |p: f64| ns[((ns.len() - 1) as f64 * p).round() as usize] as f64 / 1e3;
    json!({ "p50_us": at(0.5), "p99_us": at(0.99), "p999_us": at(0.999), "max_us": at(1.0) })
}

/// Wake lateness of the controller's periodic loop over `ticks` ticks.
struct LoopSample {
    late_ns: Vec<u64>,
    overruns: u64,
    report: os::RtReport,
}

/// Run the controller's periodic loop for `ticks` ticks (under whatever load is running).
fn sample_rust(opts: &LoopBenchOptions, ticks: usize) -> LoopSample {
    let rt = opts.rt;
    let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
    let handle = std::thread::Builder::new()
        .name("hitl-bench-rt".into())
        .spawn(move || {
            let report = os::apply(&rt);
            let queue = ArrayQueue::<[f64; 8]>::new(1024);
            let mut late = Vec::with_capacity(ticks);
            let mut overruns = 0u64;
            let mut buf = [0u8; 64];
            let mut clock = Periodic::new(period, rt.spin);
            for _ in 0..ticks {
                let wake = clock.wait();
                late.push(wake.late_ns);
                overruns += u64::from(wake.overrun);
                // Tick-sized work: encode a setpoint, push telemetry.
                let q = [wake.tick as f64 * 1e-6; DOF];
                for (j, v) in q.iter().enumerate() {
                    buf[j * 4..j * 4 + 4].copy_from_slice(&(*v as f32).to_le_bytes());
                }
                let _ = queue.force_push([q[0], q[1], q[2], q[3], q[4], q[5], q[6], 0.0]);
                std::hint::black_box(&buf);
            }
            LoopSample { late_ns: late, overruns, report }
        })
        .expect("bench thread");
    handle.join().unwrap_or(LoopSample {
        late_ns: Vec::new(),
        overruns: 0,
        report: os::RtReport::default(),
    })
}

impl LoopSample {
    fn merge(&mut self, other: LoopSample) {
        self.late_ns.extend(other.late_ns);
        self.overruns += other.overruns;
        self.report = other.report;
    }

    fn to_json(&self) -> Value {
        let mut v = percentiles_us(self.late_ns.clone());
        v["overruns"] = json!(self.overruns);
        v["ticks"] = json!(self.late_ns.len());
        v["rt"] = json!(self.report.summary());
        v["fallbacks"] = json!(self.report.fallbacks);
        v
    }
}

/// A cyclictest latency histogram: (microseconds, count) buckets and the true maximum, read
/// from its `--histfile` (one `LATENCY_US COUNT` line per microsecond, `#` comments; the
/// `# Max Latencies:` line gives the true maximum).
#[derive(Debug, Default)]
struct Histogram {
    buckets: std::collections::BTreeMap<u64, u64>,
    max_us: Option<f64>,
}

impl Histogram {
    fn parse(text: &str) -> Option<Histogram> {
        let mut h = Histogram::default();
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("# Max Latencies:") {
                h.max_us = rest.trim().parse::<f64>().ok();
                continue;
            }
            if line.starts_with('#') {
                continue;
            }
            let mut it = line.split_whitespace();
            let (Some(us), Some(n)) = (it.next(), it.next()) else { continue };
            *h.buckets.entry(us.parse::<u64>().ok()?).or_default() += n.parse::<u64>().ok()?;
        }
        Some(h)
    }

    fn merge(&mut self, other: Histogram) {
        for (us, n) in other.buckets {
            *self.buckets.entry(us).or_default() += n;
        }
        self.max_us = match (self.max_us, other.max_us) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
    }

    fn to_json(&self) -> Option<Value> {
        let total: u64 = self.buckets.values().sum();
        if total == 0 {
            return None;
        }
        let at = |p: f64| {
            let rank = ((total - 1) as f64 * p).round() as u64;
            let mut seen = 0;
            for (us, n) in &self.buckets {
                seen += n;
                if seen > rank {
                    return *us as f64;
                }
            }
            self.buckets.keys().last().map_or(0.0, |us| *us as f64)
        };
        Some(json!({
            "p50_us": at(0.5),
            "p99_us": at(0.99),
            "p999_us": at(0.999),
            "max_us": self.max_us.unwrap_or_else(|| at(1.0)),
            "cycles": total,
        }))
    }
}

/// cyclictest with the loop's period, tick count, priority, memory locking and CPU, under the
/// same load: the machine's wake-up floor (microsecond histogram; its lateness is measured like
/// the loop's, wake-up time minus the absolute deadline).
fn sample_cyclictest(opts: &LoopBenchOptions, ticks: usize) -> Result<Histogram, String> {
    let interval_us = (1e6 / opts.rate_hz).round() as u64;
    let hist = std::env::temp_dir().join(format!("hitl-cyclictest-{}.txt", std::process::id()));
    let mut cmd = Command::new("cyclictest");
    cmd.args(["-q", "-t", "1"])
        .arg(format!("--interval={interval_us}"))
        .arg(format!("--loops={ticks}"))
        .arg("--histogram=100000")
        .arg(format!("--histfile={}", hist.display()));
    if opts.rt.lock_memory {
        cmd.arg("--mlockall");
    }
    // cyclictest's priority 0 is the normal scheduler, as the loop's `None`.
    cmd.arg(format!("--priority={}", opts.rt.fifo_priority.unwrap_or(0)));
    if let Some(cpu) = opts.rt.cpu {
        cmd.arg(format!("--affinity={cpu}"));
    }
    let out = cmd.output();
    let text = std::fs::read_to_string(&hist).unwrap_or_default();
    let _ = std::fs::remove_file(&hist);
    match out {
        Ok(o) if o.status.success() => Histogram::parse(&text).ok_or_else(|| {
            format!("cyclictest wrote no histogram: {}", String::from_utf8_lossy(&o.stderr).trim())
        }),
        Ok(o) => Err(format!("cyclictest failed: {}", String::from_utf8_lossy(&o.stderr).trim())),
        Err(e) => {
            Err(format!("cannot run cyclictest ({e}): install Debian's rt-tests (make setup does)"))
        }
    }
}

/// Rounds a case's time is cut into. hitl's loop and cyclictest take turns (the order flips
/// each round) under the same load threads, so a shared VM's slow seconds fall on both alike:
/// run one after the other, the two saw different minutes of a machine whose steal time swings
/// their p99 by 2x from one run to the next.
const ROUNDS: usize = 6;

/// hitl's loop and cyclictest, interleaved in [`ROUNDS`] rounds (each `seconds / ROUNDS`).
fn measure_side_by_side(opts: &LoopBenchOptions) -> (Value, Value) {
    let ticks = ((opts.seconds * opts.rate_hz) / ROUNDS as f64).round().max(1.0) as usize;
    let (hitl, floor) = under_load(opts.load, || {
        let mut hitl = LoopSample { late_ns: Vec::new(), overruns: 0, report: Default::default() };
        let mut floor: Result<Histogram, String> = Ok(Histogram::default());
        for round in 0..ROUNDS {
            let cyclictest = |floor: &mut Result<Histogram, String>| {
                if let Ok(f) = floor {
                    match sample_cyclictest(opts, ticks) {
                        Ok(h) => f.merge(h),
                        Err(e) => *floor = Err(e),
                    }
                }
            };
            if round % 2 == 1 {
                cyclictest(&mut floor);
            }
            hitl.merge(sample_rust(opts, ticks));
            if round % 2 == 0 {
                cyclictest(&mut floor);
            }
        }
        (hitl, floor)
    });
    let floor = match floor {
        Ok(h) => h.to_json().unwrap_or_else(|| json!({ "error": "cyclictest counted nothing" })),
        Err(e) => json!({ "error": e }),
    };
    (hitl.to_json(), floor)
}

/// hitl's lateness over cyclictest's at one percentile (a 1 us floor on the divisor: cyclictest
/// counts whole microseconds).
fn floor_ratio(hitl: &Value, cyclictest: &Value, key: &str) -> Option<f64> {
    Some(hitl.get(key)?.as_f64()? / cyclictest.get(key)?.as_f64()?.max(1.0))
}

/// The same loop in plain Python: `time.sleep(period)` per iteration, lateness measured against
/// the absolute schedule the controller keeps.
fn measure_python(opts: &LoopBenchOptions, python: &str) -> Value {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/bench_loop.py");
    let out = under_load(opts.load, || {
        Command::new(python)
            .arg(script)
            .arg(opts.seconds.to_string())
            .arg(opts.rate_hz.to_string())
            .output()
    });
    match out {
        Ok(o) if o.status.success() => serde_json::from_slice(&o.stdout)
            .unwrap_or_else(|e| json!({ "error": format!("bad output from {script}: {e}") })),
        Ok(o) => json!({ "error": String::from_utf8_lossy(&o.stderr).trim().to_string() }),
        Err(e) => json!({ "error": format!("cannot run {python}: {e}") }),
    }
}

/// Run the benchmark: the controller's loop side by side with cyclictest, then the Python loop,
/// each idle and (when asked) under load.
pub fn run(opts: &LoopBenchOptions) -> Value {
    let mut cases = Vec::new();
    let loads: &[bool] = if opts.load { &[false, true] } else { &[false] };
    for &load in loads {
        let o = LoopBenchOptions { load, ..opts.clone() };
        let (rust, floor) = measure_side_by_side(&o);
        let python = opts.python.as_deref().map(|py| measure_python(&o, py));
        // The Python loop drifts (its lateness against the schedule grows without bound), so
        // the ratio compares its per-iteration jitter with hitl's wake lateness, both p99.
        let ratio = python.as_ref().and_then(|p| {
            Some(
                p.get("interval_jitter_p99_us")?.as_f64()?
                    / rust.get("p99_us")?.as_f64()?.max(1e-3),
            )
        });
        cases.push(json!({
            "load": load,
            "hitl": rust,
            "cyclictest": floor,
            "p50_ratio_hitl_over_cyclictest": floor_ratio(&rust, &floor, "p50_us"),
            "p99_ratio_hitl_over_cyclictest": floor_ratio(&rust, &floor, "p99_us"),
            "python_sleep_loop": python,
            "p99_ratio_python_jitter_over_hitl_lateness": ratio,
        }));
    }
    json!({
        "bench": "loop",
        "rate_hz": opts.rate_hz,
        "seconds": opts.seconds,
        "cases": cases,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyclictest_histograms_give_percentiles() {
        let text = "# Histogram\n000000 000000\n000010 000050\n000011 000049\n000090 000001\n\
                    # Total: 000000100\n# Max Latencies: 00093\n";
        let v = Histogram::parse(text).and_then(|h| h.to_json()).expect("percentiles");
        assert_eq!(v["p50_us"], 11.0);
        assert_eq!(v["p99_us"], 11.0);
        assert_eq!(v["p999_us"], 90.0);
        assert_eq!(v["max_us"], 93.0);
        assert_eq!(v["cycles"], 100);
        assert!(Histogram::parse("# Histogram\n").and_then(|h| h.to_json()).is_none());
        let hitl = json!({ "p50_us": 16.5 });
        assert_eq!(floor_ratio(&hitl, &v, "p50_us"), Some(1.5));
    }

    #[test]
    fn interleaved_rounds_pool_their_histograms() {
        let mut pooled = Histogram::default();
        for text in [
            "000010 000060\n# Max Latencies: 00012\n",
            "000010 000030\n000020 000010\n# Max Latencies: 00025\n",
        ] {
            pooled.merge(Histogram::parse(text).expect("histogram"));
        }
        let v = pooled.to_json().expect("percentiles");
        assert_eq!(v["cycles"], 100);
        assert_eq!(v["p50_us"], 10.0);
        assert_eq!(v["p99_us"], 20.0);
        assert_eq!(v["max_us"], 25.0);
    }
}
