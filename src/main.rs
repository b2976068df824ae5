//! `hitl`: the DreamSat-Bench hardware-in-the-loop controller.
//!
//! This file only parses the command line and hands each subcommand to its module in [`cli`];
//! every subcommand returns one of the contract's exit codes ([`exit`]).

use clap::{Parser, Subcommand};
use hitl::{cli, exit};
use std::process::ExitCode;

/// Hardware-in-the-loop controller for the DreamSat-Bench xArm7 testbed.
///
/// Without `--arm`, `run` drives the embedded MuJoCo stub on loopback: a real arm moves only when
/// the operator names its address.
#[derive(Debug, Parser)]
#[command(name = "hitl", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Plan an orbital trajectory (ROE -> HCW -> lab frame -> IK) and write it as NPZ.
    Plan(cli::plan::PlanArgs),
    /// Preflight a trajectory: limits, clearances, steps. Exit 0 safe, 3 unsafe, 2 bad input.
    Check(cli::check::CheckArgs),
    /// Serve the MuJoCo stub of arm, camera and light on loopback (xArm protocol).
    Stub(cli::stub::StubArgs),
    /// Bring the arm to the lab's rest pose along a planned, checked path (the embedded stub unless
    /// --arm is given).
    Park(cli::park::ParkArgs),
    /// Play a trajectory with every interlock armed (the embedded stub unless --arm is given).
    Run(cli::run::RunArgs),
    /// `hitl run` with a recording: the same flags, and a default file under runs/.
    Record(cli::run::RunArgs),
    /// Summarise a recording: summary JSON, plots and an index.html.
    Report(cli::report::ReportArgs),
    /// Pose metrics of a recording, as the paper defines them.
    Eval(cli::eval::EvalArgs),
    /// Benchmarks; `--json` prints one JSON object of figures.
    Bench(cli::bench::BenchArgs),
    /// Calibrate the camera mount and target pose from views of the board (--print-board: draw it).
    #[cfg(feature = "stub")]
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Commission devices: list ports and cameras, check each named device answers. Moves nothing.
    Probe(cli::probe::ProbeArgs),
    /// SITL campaigns from a manifest: run (resumable, N at a time), collect, slurm, list.
    Campaign(cli::campaign::CampaignArgs),
    /// Export recordings: `hitl export lerobot RUN.mcap... --out DIR` (a LeRobot v3.0 dataset).
    Export(cli::export::ExportArgs),
    /// List the targets (built-ins, or the named ones): faces, size, symmetry and parts.
    Targets(cli::targets::TargetsArgs),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { exit::BAD_INPUT } else { exit::OK };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    let code = match cli.command {
        Command::Plan(args) => cli::plan::run(args),
        Command::Check(args) => cli::check::run(args),
        Command::Stub(args) => cli::stub::run(args),
        Command::Park(args) => cli::park::run(args),
        Command::Run(args) => cli::run::run(args, false),
        Command::Record(args) => cli::run::run(args, true),
        Command::Report(args) => cli::report::run(args),
        Command::Eval(args) => cli::eval::run(args),
        Command::Bench(args) => cli::bench::run(args),
        Command::Probe(args) => cli::probe::run(args),
        #[cfg(feature = "stub")]
        Command::Calibrate(args) => cli::calibrate::run(args),
        Command::Campaign(args) => cli::campaign::run(args),
        Command::Export(args) => cli::export::run(args),
        Command::Targets(args) => cli::targets::run(args),
    };
    ExitCode::from(code)
}
