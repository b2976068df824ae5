//! `hitl bench`: the project's benchmarks. Each prints its figures; `--json` prints one JSON
//! object (the README quotes these with the command that produced them).

use crate::bench::loop_timing::{self, LoopBenchOptions};
use crate::exit;
use crate::rt::RtOptions;
use std::time::Duration;

/// Which benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Which {
    /// Real-time loop wake-up lateness (p50/p99/p99.9/max, overruns), idle and under load, side
    /// by side with a plain Python sleep loop.
    Loop,
}

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// The benchmark to run.
    #[arg(value_enum)]
    pub which: Which,
    /// How long to measure, seconds.
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub seconds: f64,
    /// Loop rate, Hz.
    #[arg(long, default_value_t = 250.0, value_name = "HZ")]
    pub rate: f64,
    /// Also measure under recorder/perception-like load on every core.
    #[arg(long)]
    pub load: bool,
    /// SCHED_FIFO priority for the loop thread (0: normal scheduler).
    #[arg(long, default_value_t = 80, value_name = "PRIO")]
    pub rt_priority: i32,
    /// Spin for the last N microseconds before each deadline.
    #[arg(long, default_value_t = 0, value_name = "US")]
    pub spin_us: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn venv_python() -> Option<String> {
    let p = env!("HITL_VENV_PYTHON");
    std::path::Path::new(p).exists().then(|| p.to_string())
}

pub fn run(args: BenchArgs) -> u8 {
    if !(args.seconds > 0.0 && args.seconds.is_finite()) {
        eprintln!("hitl bench: --seconds must be positive");
        return exit::BAD_INPUT;
    }
    if !(50.0..=1000.0).contains(&args.rate) {
        eprintln!("hitl bench: --rate must be within 50-1000 Hz");
        return exit::BAD_INPUT;
    }
    let figures = match args.which {
        Which::Loop => loop_timing::run(&LoopBenchOptions {
            seconds: args.seconds,
            rate_hz: args.rate,
            load: args.load,
            rt: RtOptions {
                fifo_priority: (args.rt_priority > 0).then_some(args.rt_priority),
                lock_memory: true,
                cpu: None,
                spin: Duration::from_micros(args.spin_us),
            },
            python: venv_python().or_else(|| Some("python3".into())),
        }),
    };
    if args.json {
        println!("{figures}");
    } else {
        println!("{}", serde_json::to_string_pretty(&figures).unwrap_or_default());
    }
    exit::OK
}
