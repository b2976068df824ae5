//! `hitl campaign`: the paper's SITL sweeps from one manifest (docs/campaigns.md).
//!
//! - [`manifest`]: the TOML manifest, its cases and their ids;
//! - [`run`]: `hitl campaign run`, every case as plan, SITL run and eval child processes;
//! - [`child`]: those children, in process groups of their own, ended with the campaign;
//! - [`check`]: manifest values checked by the parsers of the flags they become;
//! - [`store`]: the campaign folder, atomic writes, which cases are done;
//! - [`collect`]: `hitl campaign collect`, results.csv; [`plots`]: its SVG plots;
//! - [`slurm`]: `hitl campaign slurm`, an sbatch job array with one task per case;
//! - [`phase`]: a Sun phase window turned into the arc `hitl plan --arc` plays.

pub mod check;
pub mod child;
pub mod collect;
pub mod manifest;
pub mod phase;
pub mod plots;
pub mod run;
pub mod slurm;
pub mod store;

use crate::exit;
use std::path::PathBuf;

/// Flags of `hitl campaign`.
#[derive(Debug, clap::Args)]
pub struct CampaignArgs {
    #[command(subcommand)]
    pub command: CampaignCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum CampaignCommand {
    /// Play every case (plan, SITL run with recording, eval), resuming where a previous run stopped.
    Run(RunArgs),
    /// Tabulate a campaign folder: DIR/results.csv and the paper's plots under DIR/plots/.
    Collect(CollectArgs),
    /// Write an sbatch script running the cases as a Slurm job array (one task per case).
    Slurm(SlurmArgs),
    /// List a manifest's cases (index, id, parameters) without running anything.
    List(ListArgs),
}

/// Flags of `hitl campaign run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The manifest (TOML: [run] fixed parameters, [matrix] lists; docs/campaigns.md).
    pub manifest: PathBuf,
    /// Campaign folder: one folder per case under DIR/cases/, results.csv after collect.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Cases at a time (default: half the cores, at least 1, so every run's real-time loop,
    /// renderer and estimator keep room).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Play case I alone (0-based, as `hitl campaign list` numbers them; a Slurm array task).
    #[arg(long, value_name = "I")]
    pub index: Option<usize>,
    /// Plain progress lines instead of a progress bar (logs, batch jobs).
    #[arg(long)]
    pub plain: bool,
}

/// Flags of `hitl campaign collect`.
#[derive(Debug, clap::Args)]
pub struct CollectArgs {
    /// A campaign folder written by `hitl campaign run --out DIR`.
    pub dir: PathBuf,
}

/// Flags of `hitl campaign list`.
#[derive(Debug, clap::Args)]
pub struct ListArgs {
    /// The manifest.
    pub manifest: PathBuf,
    /// Print one JSON object: the campaign's name and each case's index, id, full definition,
    /// varied keys, the Sun it plays under and the phase angles its arc sees.
    #[arg(long)]
    pub json: bool,
}

/// Flags of `hitl campaign slurm`.
#[derive(Debug, clap::Args)]
pub struct SlurmArgs {
    /// The manifest.
    pub manifest: PathBuf,
    /// Campaign folder (on a file system every node sees).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Also submit the script with sbatch.
    #[arg(long)]
    pub submit: bool,
    /// Most array tasks running at once (the `%LIMIT` of `--array`; at least 1).
    #[arg(long, value_name = "N", default_value_t = 16)]
    pub limit: u64,
    /// CPUs per task (a run's loop, renderer and estimator: 2 keeps the loop a core).
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub cpus_per_task: u64,
    /// Memory per task: a whole number with an optional unit K, M, G or T, e.g. 4G.
    #[arg(long, value_name = "SIZE", default_value = "4G")]
    pub mem: String,
    /// Time limit per task in minutes, 1 to 525600 (365 days; default: from the longest case's
    /// duration).
    #[arg(long, value_name = "MIN")]
    pub time_min: Option<u64>,
    /// Slurm partition (letters, digits and _.-; a comma-separated list of them).
    #[arg(long, value_name = "NAME")]
    pub partition: Option<String>,
    /// Slurm account (letters, digits and _.-).
    #[arg(long, value_name = "NAME")]
    pub account: Option<String>,
    /// Folder of the shared libraries hitl loads (MuJoCo, ONNX Runtime, Orbbec SDK); default:
    /// .deps/lib of the checkout the binary was built in.
    #[arg(long, value_name = "DIR")]
    pub lib_dir: Option<PathBuf>,
    /// Where to write the script (default: DIR/slurm/NAME.sbatch).
    #[arg(long, value_name = "FILE")]
    pub script: Option<PathBuf>,
}

/// Run `hitl campaign`.
pub fn run(args: CampaignArgs) -> u8 {
    match args.command {
        CampaignCommand::Run(a) => run_cmd(a),
        CampaignCommand::Collect(a) => collect::run(&a.dir),
        CampaignCommand::Slurm(a) => slurm::run(&a),
        CampaignCommand::List(a) => list(&a),
    }
}

/// The manifest and its text, or the exit code after saying why not.
pub fn load(path: &std::path::Path) -> Result<(manifest::Manifest, String), u8> {
    let refuse = |e: String| {
        crate::errln!("hitl campaign: {e}");
        exit::BAD_INPUT
    };
    let bytes = store::read_capped(path, manifest::MAX_MANIFEST_BYTES)
        .map_err(|e| refuse(format!("{}: {e}", path.display())))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| refuse(format!("{}: not UTF-8 text", path.display())))?;
    let m = manifest::load_text(path, &text).map_err(|e| refuse(e.to_string()))?;
    Ok((m, text))
}

fn run_cmd(a: RunArgs) -> u8 {
    let (m, text) = match load(&a.manifest) {
        Ok(x) => x,
        Err(code) => return code,
    };
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            crate::errln!("hitl campaign run: cannot find this executable: {e}");
            return exit::BAD_INPUT;
        }
    };
    if a.jobs == Some(0) {
        crate::errln!("hitl campaign run: --jobs must be at least 1");
        return exit::BAD_INPUT;
    }
    let opts = run::RunOptions {
        out: a.out,
        jobs: a.jobs.unwrap_or_else(run::default_jobs),
        index: a.index,
        plain: a.plain,
        exe,
    };
    run::run(&m, &text, &opts)
}

fn list(a: &ListArgs) -> u8 {
    let (m, _) = match load(&a.manifest) {
        Ok(x) => x,
        Err(code) => return code,
    };
    if a.json {
        let mut cases = Vec::new();
        // Cases that differ only in target or estimator share their Sun: found once.
        let mut found: std::collections::HashMap<String, Result<phase::CaseSun, String>> =
            std::collections::HashMap::new();
        for c in m.cases() {
            let key = ["preset", "range_m", "arc_deg", "sun_phase_deg", "phase_angle_deg"]
                .map(|k| c.cell(k))
                .join("|");
            let sun = found.entry(key).or_insert_with(|| run::case_sun(&c)).clone();
            let (sun, phase) = match sun {
                Ok(s) => (
                    serde_json::json!(s.sun_eci),
                    serde_json::json!([s.phase_angle_deg.0, s.phase_angle_deg.1]),
                ),
                Err(e) => (serde_json::Value::Null, serde_json::json!({ "error": e })),
            };
            cases.push(serde_json::json!({
                "index": c.index,
                "id": c.id,
                "params": c.params,
                "varied": c.varied,
                "sun_eci": sun,
                "phase_angle_deg": phase,
            }));
        }
        let out = serde_json::json!({ "campaign": m.name, "cases": cases });
        crate::outln!("{out}");
        return exit::OK;
    }
    crate::outln!("campaign {}: {} cases", m.name, m.len());
    for c in m.cases() {
        let what: Vec<String> = c.varied.iter().map(|k| format!("{k}={}", c.cell(k))).collect();
        crate::outln!("{:4}  {}  {}", c.index, c.id, what.join(" "));
    }
    exit::OK
}
