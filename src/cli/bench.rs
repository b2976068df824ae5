//! `hitl bench`: the project's benchmarks. Each prints its figures; `--json` prints one JSON
//! object (the README quotes these with the command that produced them).

use crate::bench::loop_timing::{self, LoopBenchOptions};
use crate::exit;
use crate::rt::RtOptions;
use hitl_record::{ChunkCompression, RecorderConfig};
use std::time::Duration;

/// Which benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Which {
    /// Real-time loop wake-up lateness (p50/p99/p99.9/max, overruns), idle and under load, side
    /// by side with cyclictest (the machine's floor; ratios hitl/cyclictest at p50 and p99) and a
    /// plain Python sleep loop.
    Loop,
    /// Loading a 100 000-waypoint NPZ and time-parametrising it, side by side with numpy's load.
    Npz,
    /// IK for a 3600-waypoint orbit (the Python side: see README).
    Ik,
    /// servo_j round trips on loopback against the stub, the command rate it sustains, its
    /// real-time factor.
    Protocol,
    /// Simulated camera frames/s (colour + depth + mask) at 320x256, 1280x800 and 1280x1024 from
    /// MuJoCo's renderer next to the ray cast, idle and with --load; trigger-to-frame latency;
    /// wall and CPU ms per 1280x800 frame of the render and of the Orbbec depth model.
    Render,
    /// Sustained recording of depth + colour at 30 fps plus 250 Hz telemetry, side by side with
    /// numpy savez_compressed per depth frame.
    Record,
    /// The ICP tracker on a fly-around of each --target-model: the paper's metrics, failures,
    /// frames/s, registration time, against issue 23's goal. Frames drawn by the test rasteriser
    /// at --camera-preset/--size, depth as rendered or through the Orbbec model (--depth-model),
    /// the exact silhouette or the controller's drawn mask (--mask) (docs/perception.md).
    Tracker,
    /// Pose accuracy (paper's metrics) on synthetic fly-arounds at 5, 10, 25 and 50 m.
    Accuracy,
    /// The simulated clock's real-time factor on a campaign case: a 30 s fly-around with 151
    /// captures, ICP, recorded, `--clock sim`, at 320x256 and 1280x800 (--size: one size),
    /// --range-m, the first --target-model (default asymmetric); the loop's and the whole run's.
    Rtf,
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
    /// 1-99: Linux's SCHED_FIFO range.
    #[arg(long, default_value_t = 80, value_name = "PRIO",
          value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// Spin for the last N microseconds before each deadline.
    #[arg(long, default_value_t = 0, value_name = "US")]
    pub spin_us: u64,
    /// Image size for the tracker, accuracy and rtf benchmarks (default: accuracy 320x256;
    /// tracker the --camera-preset's own size; rtf 320x256 and 1280x800).
    #[arg(long, value_name = "WxH")]
    pub size: Option<String>,
    /// Tracker: the simulated camera's intrinsics preset, scaled to --size: wfov, nfov or orbbec
    /// (1280x800, f = 640 px).
    #[arg(long, default_value = "wfov", value_name = "wfov|nfov|orbbec")]
    pub camera_preset: String,
    /// Tracker: depth as rendered (ideal) or through the Orbbec Gemini 305 model (orbbec), as
    /// `hitl run --depth-model`.
    #[arg(long, default_value = "ideal", value_name = "ideal|orbbec")]
    pub depth_model: crate::devices::SimDepthModel,
    /// Tracker: the mask the tracker gets: sim (the exact silhouette) or rendered (drawn as
    /// `hitl run --mask rendered` draws it, lab equal to the truth, grown by --mask-margin-px).
    #[arg(long, default_value = "sim", value_name = "sim|rendered")]
    pub mask: String,
    /// Tracker: the rendered mask's margin, pixels.
    #[arg(long, default_value_t = crate::capture::mask::DEFAULT_MARGIN_PX, value_name = "N")]
    pub mask_margin_px: u32,
    /// Tracker: a target (built-in name or OBJ/STL file), repeatable; default every built-in.
    /// Rtf: the first one (default asymmetric).
    #[arg(long, value_name = "NAME|FILE")]
    pub target_model: Vec<String>,
    /// Tracker and rtf: the fly-around's nearest range, real metres (the lab scale is the
    /// paper's workspace scale at this range).
    #[arg(long, default_value_t = 10.0, value_name = "M")]
    pub range_m: f64,
    /// Frames per model for the tracker and accuracy benchmarks.
    #[arg(long, default_value_t = 30, value_name = "N")]
    pub frames: usize,
    /// Chunk compression for the record benchmark: none, lz4, zstd or zstd:LEVEL (1-19).
    #[arg(long, default_value_t = RecorderConfig::default().compression, value_name = "NAME")]
    pub compression: ChunkCompression,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Run a side-by-side Python script under scripts/ and parse its one JSON object.
fn python_figures(python: &str, script: &str, args: &[String]) -> serde_json::Value {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/").to_string() + script;
    match std::process::Command::new(python).arg(&path).args(args).output() {
        Ok(o) if o.status.success() => serde_json::from_slice(&o.stdout).unwrap_or_else(
            |e| serde_json::json!({ "error": format!("{script} printed no JSON object: {e}") }),
        ),
        Ok(o) => {
            serde_json::json!({ "error": String::from_utf8_lossy(&o.stderr).trim().to_string() })
        }
        Err(e) => serde_json::json!({ "error": format!("cannot run {python}: {e}") }),
    }
}

fn venv_python() -> Option<String> {
    let p = env!("HITL_VENV_PYTHON");
    std::path::Path::new(p).exists().then(|| p.to_string())
}

fn parse_size(s: &str) -> Option<(u32, u32)> {
    let (w, h) = s.split_once('x')?;
    let (w, h) = (w.parse::<u32>().ok()?, h.parse::<u32>().ok()?);
    (w > 0 && h > 0 && w <= 8192 && h <= 8192).then_some((w, h))
}

/// The tracker bench's options from the flags.
#[cfg(feature = "stub")]
fn tracker_options(
    args: &BenchArgs,
    size: Option<(u32, u32)>,
) -> Result<hitl_perception::tracker_bench::TrackerBenchOptions, String> {
    use hitl_sim_stub::camera::Preset;
    let preset = Preset::from_name(&args.camera_preset).ok_or_else(|| {
        format!("--camera-preset {:?}: expected wfov, nfov or orbbec", args.camera_preset)
    })?;
    let native = preset.intrinsics();
    let (w, h) = size.unwrap_or((native.width, native.height));
    let rendered_mask = match args.mask.as_str() {
        "sim" => None,
        "rendered" => Some(args.mask_margin_px),
        other => return Err(format!("--mask {other:?}: expected sim or rendered")),
    };
    if !(args.range_m.is_finite() && args.range_m > 0.0) {
        return Err(format!("--range-m must be a positive number, got {}", args.range_m));
    }
    let targets = if args.target_model.is_empty() {
        hitl_perception::models::SPACECRAFT_NAMES
            .iter()
            .chain(hitl_perception::models::BUILTIN_NAMES.iter())
            .map(|s| s.to_string())
            .collect()
    } else {
        args.target_model.clone()
    };
    for t in &targets {
        hitl_perception::TargetModel::from_spec(t).map_err(|e| format!("--target-model: {e}"))?;
    }
    Ok(hitl_perception::tracker_bench::TrackerBenchOptions {
        intrinsics: preset.at(w, h),
        depth_model: args.depth_model.to_string(),
        rendered_mask,
        targets,
        range_m: args.range_m,
        frames: args.frames,
    })
}

pub fn run(args: BenchArgs) -> u8 {
    if !(args.seconds > 0.0 && args.seconds.is_finite()) {
        crate::errln!("hitl bench: --seconds must be positive");
        return exit::BAD_INPUT;
    }
    if !(50.0..=1000.0).contains(&args.rate) {
        crate::errln!("hitl bench: --rate must be within 50-1000 Hz");
        return exit::BAD_INPUT;
    }
    let size = match args.size.as_deref().map(parse_size) {
        Some(Some(s)) => Some(s),
        Some(None) => {
            crate::errln!("hitl bench: --size must be WIDTHxHEIGHT, e.g. 320x256");
            return exit::BAD_INPUT;
        }
        None => None,
    };
    let (width, height) = size.unwrap_or((320, 256));
    let python = venv_python().unwrap_or_else(|| "python3".into());
    let figures = match args.which {
        Which::Npz => {
            let rust = hitl_trajectories::bench::bench_npz(100_000);
            let dir = hitl_trajectories::bench::bench_dir();
            let files: Vec<String> = ["stored", "deflated"]
                .iter()
                .map(|k| dir.join(format!("traj-100000-{k}.npz")).display().to_string())
                .collect();
            let numpy = python_figures(&python, "bench_npz.py", &files);
            serde_json::json!({ "bench": "npz", "hitl": rust, "numpy": numpy })
        }
        Which::Ik => hitl_trajectories::planner::bench::bench_ik(3600),
        #[cfg(feature = "stub")]
        Which::Protocol => {
            let lab = hitl_trajectories::lab::LabConfig::default();
            match hitl_sim_stub::mujoco_plant::MujocoPlant::new(&lab, None) {
                Ok(plant) => hitl_sim_stub::bench_protocol(Box::new(plant), Default::default())
                    .unwrap_or_else(|e| serde_json::json!({ "error": e.to_string() })),
                Err(e) => serde_json::json!({ "error": e.to_string() }),
            }
        }
        #[cfg(feature = "stub")]
        Which::Render => {
            let load = |f: &mut dyn FnMut()| crate::bench::load::under_load(true, f);
            hitl_sim_stub::camera::bench_render(
                args.load.then_some(&load as hitl_sim_stub::camera::bench::UnderLoad<'_>),
            )
        }
        #[cfg(not(feature = "stub"))]
        Which::Protocol | Which::Render | Which::Tracker => {
            crate::errln!("hitl bench: this build has no stub");
            return exit::BAD_INPUT;
        }
        Which::Record => {
            let rust = hitl_record::bench::bench_record(args.seconds, args.compression);
            let secs = args.seconds.to_string();
            let numpy =
                python_figures(&python, "bench_record_numpy.py", &["--seconds".into(), secs]);
            serde_json::json!({ "bench": "record", "hitl": rust, "numpy_savez_compressed": numpy })
        }
        #[cfg(feature = "stub")]
        Which::Tracker => match tracker(&args, size) {
            Ok(figures) => figures,
            Err(e) => {
                crate::errln!("hitl bench tracker: {e}");
                return exit::BAD_INPUT;
            }
        },
        Which::Accuracy => hitl_perception::bench::bench_accuracy(
            &[5.0, 10.0, 25.0, 50.0],
            width,
            height,
            args.frames,
            0.077,
        ),
        Which::Rtf => rtf(&args, size),
        Which::Loop => loop_timing::run(&LoopBenchOptions {
            seconds: args.seconds,
            rate_hz: args.rate,
            load: args.load,
            rt: RtOptions {
                spin: Duration::from_micros(args.spin_us),
                ..RtOptions::with_priority(args.rt_priority)
            },
            python: venv_python().or_else(|| Some("python3".into())),
        }),
    };
    if args.json {
        crate::outln!("{figures}");
    } else {
        crate::outln!("{}", serde_json::to_string_pretty(&figures).unwrap_or_default());
    }
    exit::OK
}

/// `hitl bench tracker`: the ICP tracker on a camera's frames, the Orbbec stereo depth model
/// applied when `--depth-model orbbec` asks for it.
#[cfg(feature = "stub")]
fn tracker(args: &BenchArgs, size: Option<(u32, u32)>) -> Result<serde_json::Value, String> {
    let o = tracker_options(args, size)?;
    let noise = hitl_sim_stub::camera::NoiseModel {
        depth_model: hitl_sim_stub::camera::DepthModel::Orbbec(
            hitl_sim_stub::camera::StereoDepth::GEMINI_305,
        ),
        seed: 23,
        ..Default::default()
    };
    let orbbec =
        move |i: u64, d: &mut [f32], k: &hitl_hal::Intrinsics| noise.draw(i).apply_depth(d, k);
    let degrade: Option<hitl_perception::tracker_bench::DepthModel<'_>> = match args.depth_model {
        crate::devices::SimDepthModel::Orbbec => Some(&orbbec),
        crate::devices::SimDepthModel::Ideal => None,
    };
    Ok(hitl_perception::tracker_bench::run(&o, degrade))
}

/// `hitl bench rtf`: the simulated clock's real-time factor of a campaign case, played by this
/// binary in a scratch folder that is removed afterwards.
fn rtf(args: &BenchArgs, size: Option<(u32, u32)>) -> serde_json::Value {
    let sizes = size.map_or(vec![(320, 256), (1280, 800)], |s| vec![s]);
    let target = args.target_model.first().cloned().unwrap_or_else(|| "asymmetric".into());
    let o = crate::bench::rtf::RtfOptions { sizes, range_m: args.range_m, target };
    let dir = std::env::temp_dir().join(format!("hitl-bench-rtf-{}", std::process::id()));
    let figures = match std::env::current_exe() {
        Ok(exe) => crate::bench::rtf::run(&o, &exe, &dir),
        Err(e) => serde_json::json!({ "error": format!("this binary's path: {e}") }),
    };
    let _ = std::fs::remove_dir_all(&dir);
    figures
}
