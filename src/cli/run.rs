//! `hitl run` / `hitl record`: play a trajectory with every interlock armed.
//!
//! Without `--arm` the embedded MuJoCo stub on loopback is the target. With `--arm HOST` a real
//! xArm moves: the operator must confirm the enclosure is clear (or pass `--yes`), and the run
//! refuses when it cannot ask.

use crate::capture::mask::{MaskSource, DEFAULT_MARGIN_PX};
use crate::cli::device_flags::{DeviceFlags, LabFlags, Refusal, SimCameraFlags};
use crate::cli::reregister::ReregisterArgs;
use crate::devices::CameraSpec;
use crate::exit;
use crate::rt::RtOptions;
use crate::session::{self, ArmTarget, ClockChoice, RunRequest, StubFault, TrajectorySource};
use hitl_perception::BackendSpec;
use hitl_record::live::DEFAULT_LIVE_ADDR;
use hitl_record::{ChunkCompression, LiveConfig, RecorderConfig};
use std::io::IsTerminal;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The trajectory to play (NPZ, see docs/npz-schema.md).
    pub trajectory: PathBuf,
    #[command(flatten)]
    pub devices: DeviceFlags,
    #[command(flatten)]
    pub labs: LabFlags,
    #[command(flatten)]
    pub sim_camera: SimCameraFlags,
    /// Control rate in Hz (50-1000).
    #[arg(long, default_value_t = 250.0, value_name = "HZ")]
    pub rate: f64,
    /// Slow the trajectory down: time is stretched by 1/S, S in (0, 1].
    #[arg(long, default_value_t = 1.0, value_name = "S")]
    pub speed_scale: f64,
    /// Waypoints per second of a file without `t` (waypoint i plays at i / HZ s); refused for a
    /// file that has `t`.
    #[arg(long, value_name = "HZ")]
    pub waypoint_rate: Option<f64>,
    /// Record the run to this MCAP file (`hitl record` picks runs/run-<time>.mcap by default).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// How the recording's chunks are compressed: lz4 (fast), zstd or zstd:LEVEL (1-19,
    /// smaller files, more CPU), or none (fastest, largest); `hitl bench record --compression`
    /// measures each.
    #[arg(long, default_value_t = RecorderConfig::default().compression, value_name = "NAME")]
    pub record_compression: ChunkCompression,
    /// Pose estimation on captured frames: icp, mono (the monocular baseline: colour and mask,
    /// no depth), onnx:MODEL, socket:PATH (an external estimator listening on a unix socket,
    /// docs/perception.md), or none.
    #[arg(long, default_value = "none", value_name = "icp|mono|onnx:MODEL|socket:PATH|none")]
    pub perception: BackendSpec,
    #[command(flatten)]
    pub reregister: ReregisterArgs,
    /// Where each capture's target mask comes from: sim (the simulated camera's own; the default
    /// with --camera sim), rendered (drawn by the controller from its lab configuration, the
    /// target model and the arm's reported joints at the exposure, with the camera's intrinsics;
    /// the default with an Orbbec camera, which has no mask), or none (the estimator gets no
    /// mask). Recorded on /camera/mask and named in the run's metadata (docs/perception.md).
    #[arg(long, value_name = "sim|rendered|none")]
    pub mask: Option<MaskSource>,
    /// Pixels the rendered mask is grown by, to cover calibration and timing error.
    #[arg(long, default_value_t = DEFAULT_MARGIN_PX, value_name = "N")]
    pub mask_margin_px: u32,
    /// Target model: asymmetric, one-plane, two-planes (built in) or an OBJ/STL file.
    #[arg(long, default_value = "asymmetric", value_name = "NAME|FILE")]
    pub target_model: String,
    /// The simulated camera's depth: ideal (as rendered, every surface pixel exact; the SITL
    /// accuracy figures' setting) or orbbec (the Gemini 305's stereo depth: error growing with
    /// z^2, no depth at edges, in the projector's shadow and at grazing angles;
    /// docs/sim-camera.md).
    #[arg(long, default_value = "ideal", value_name = "ideal|orbbec")]
    pub depth_model: crate::devices::SimDepthModel,
    /// The simulated camera's scene: lab (the enclosure's twin, the studio light) or orbit (black
    /// sky, the Earth, a Sun that follows the trajectory's Sun phase); overrides the lab
    /// configuration's `[scene] kind` (docs/stub-scene.md).
    #[arg(long, value_name = "lab|orbit")]
    pub scene_kind: Option<hitl_trajectories::lab::SceneKind>,
    /// Inject a stub fault at a time into the run (repeatable): drop-connection, stall-reports,
    /// stall-replies, arm-error, deviation, estop, door-open; e.g. `--stub-fault estop@2.5`.
    #[arg(long = "stub-fault", value_name = "KIND@SECONDS")]
    pub stub_faults: Vec<StubFault>,
    /// SCHED_FIFO priority of the loop thread (0: normal scheduler).
    /// 1-99: Linux's SCHED_FIFO range.
    #[arg(long, default_value_t = 80, value_name = "PRIO",
          value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// Pin the loop thread to this CPU.
    #[arg(long, value_name = "CPU")]
    pub cpu: Option<usize>,
    /// Spin for the last N microseconds before each deadline (tighter wake-ups, one busy core).
    #[arg(long, default_value_t = 0, value_name = "US")]
    pub spin_us: u64,
    /// SITL: the embedded stub's arm powers up at these joints (7 comma-separated radians)
    /// instead of its resting pose, e.g. where a previous run left the arm. Refused with --arm.
    #[arg(long, value_name = "Q", value_parser = crate::cli::check::parse_joints,
          allow_hyphen_values = true)]
    pub stub_start_q: Option<hitl_hal::Joints>,
    /// Leave the arm where the trajectory ends. By default a completed run goes back to the lab's
    /// rest pose (`[arm] rest_q`) along a planned, checked path, so the next run starts from rest.
    #[arg(long)]
    pub no_retreat: bool,
    /// Print plain progress lines even on a terminal.
    #[arg(long)]
    pub plain: bool,
    /// Stream the run live to Foxglove (WebSocket, docs/live.md) on ADDR, IP:PORT or IP
    /// (default 127.0.0.1:8765). Write it after the trajectory, or as --live=ADDR. Loopback only
    /// unless --allow-remote. The recorder feeds it: without --record the run is recorded to
    /// runs/run-<time>.mcap, as `hitl record` does.
    #[arg(long, value_name = "ADDR", num_args = 0..=1,
          default_missing_value = "127.0.0.1:8765", value_parser = parse_live_addr)]
    pub live: Option<SocketAddr>,
    /// Allow a non-loopback --live address (the live view then answers anyone on that network).
    #[arg(long)]
    pub allow_remote: bool,
    /// Close the loop on vision: each pose estimate feeds a relative-navigation filter in the
    /// plan's frame, and guidance corrects the upcoming setpoints toward the planned relative
    /// position, inside --corridor-m of the plan and through every preflight rule; needs a plan
    /// from `hitl plan`, a camera and --perception (docs/closed-loop.md).
    #[arg(long)]
    pub closed_loop: bool,
    /// With --closed-loop: how far (lab metres) a correction may move the camera from where the
    /// preflighted plan puts it, in (0, 0.05].
    #[arg(long, default_value_t = crate::closed_loop::corridor::DEFAULT_CORRIDOR_M, value_name = "M",
          requires = "closed_loop")]
    pub corridor_m: f64,
    /// With --closed-loop, a drill of its fallback: stop the perception worker this many seconds
    /// into the playback; the closed loop must fall back to the plan (recorded) and the run
    /// complete.
    #[arg(long, value_name = "S", requires = "closed_loop")]
    pub drill_perception_stop_s: Option<f64>,
    /// With --closed-loop, a drill of its gate: from --drill-perception-offset-s on, each pose
    /// estimate the navigator takes is moved this far (lab metres) along the camera's x axis
    /// (the recorded estimates are not); the filter must reject them, and too many in a row fall
    /// back to the plan (recorded).
    #[arg(long, value_name = "M", allow_hyphen_values = true, requires = "closed_loop")]
    pub drill_perception_offset_m: Option<f64>,
    /// When --drill-perception-offset-m starts, seconds into the playback.
    #[arg(long, value_name = "S", default_value_t = 0.0, requires = "drill_perception_offset_m")]
    pub drill_perception_offset_s: f64,
    /// Which time the run lives on: realtime (the host's clock) or sim (simulated time moved
    /// tick by tick in lockstep with the embedded stub: as fast as the machine allows, and two
    /// runs of the same inputs record the same messages). sim is refused with --arm
    /// (docs/sim-clock.md).
    #[arg(long, value_enum, default_value_t = ClockChoice::Realtime)]
    pub clock: ClockChoice,
}

fn parse_live_addr(s: &str) -> Result<SocketAddr, String> {
    s.parse::<SocketAddr>()
        .or_else(|_| s.parse::<IpAddr>().map(|ip| SocketAddr::new(ip, DEFAULT_LIVE_ADDR.port())))
        .map_err(|_| {
            format!(
                "'{s}' is not an address (IP:PORT or IP; write the trajectory before --live, or \
                 --live=ADDR)"
            )
        })
}

fn default_record_path() -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    PathBuf::from("runs").join(format!("run-{secs}.mcap"))
}

pub fn run(args: RunArgs, record: bool) -> u8 {
    let reregister = match args.reregister.policy() {
        Ok(policy) => policy,
        Err(e) => {
            crate::errln!("hitl run: {e}");
            return exit::BAD_INPUT;
        }
    };
    if let Some(addr) = args.live.filter(|a| !a.ip().is_loopback() && !args.allow_remote) {
        crate::errln!(
            "hitl run: refusing to serve the live view on {addr}: not loopback (add --allow-remote \
             to mean it); nothing moved"
        );
        return exit::BAD_INPUT;
    }
    let drill_perception_offset = match args
        .drill_perception_offset_m
        .map(|m| crate::closed_loop::EstimateOffsetDrill::new(m, args.drill_perception_offset_s))
    {
        None => None,
        Some(Ok(drill)) => Some(drill),
        Some(Err(e)) => {
            crate::errln!("hitl run: {e}");
            return exit::BAD_INPUT;
        }
    };
    let arm = args.devices.arm.as_deref();
    if let (ClockChoice::Sim, Some(host)) = (args.clock, arm) {
        crate::errln!(
            "hitl run: --clock sim runs on the embedded stub only; a real arm ({host}) keeps real \
             time: use --clock realtime with --arm"
        );
        return exit::BAD_INPUT;
    }
    let labs = match args.labs.load(arm) {
        Ok(labs) => labs,
        Err(Refusal(code, m)) => {
            crate::errln!("hitl run: {m}");
            return code;
        }
    };
    let mut lab = labs.controller;
    if let Some(kind) = args.scene_kind {
        lab.scene.kind = kind;
    }
    let target = match arm_target(&args, arm) {
        Ok(target) => target,
        Err(code) => return code,
    };
    let record = match (&args.record, record) {
        (Some(path), _) => Some(path.clone()),
        (None, true) => Some(default_record_path()),
        // The live view is fed by the recorder.
        (None, false) if args.live.is_some() => Some(default_record_path()),
        (None, false) => None,
    };
    let camera = args.devices.run_camera();
    let mask = args.mask.unwrap_or(match camera {
        CameraSpec::Sim => MaskSource::Sim,
        CameraSpec::Orbbec(_) => MaskSource::Rendered,
        CameraSpec::None => MaskSource::None,
    });
    let request = RunRequest {
        trajectory: TrajectorySource::File {
            path: args.trajectory,
            waypoint_rate_hz: args.waypoint_rate,
        },
        lab,
        rate_hz: args.rate,
        speed_scale: args.speed_scale,
        target,
        record,
        record_compression: args.record_compression,
        camera,
        light: args.devices.run_light(),
        trigger: args.devices.run_trigger(),
        perception: args.perception,
        reregister,
        mask,
        mask_margin_px: args.mask_margin_px,
        camera_preset: args.sim_camera.camera_preset,
        camera_size: args.sim_camera.camera_size,
        target_model: args.target_model,
        stub_lab: labs.stub,
        depth_model: args.depth_model,
        rt: RtOptions {
            cpu: args.cpu,
            spin: Duration::from_micros(args.spin_us),
            ..RtOptions::with_priority(args.rt_priority)
        },
        retreat: !args.no_retreat,
        stub_start_q: args.stub_start_q,
        plain_progress: args.plain || !std::io::stderr().is_terminal(),
        live: args.live.map(LiveConfig::new),
        closed_loop: args.closed_loop.then(|| crate::closed_loop::ClosedLoopConfig {
            corridor_m: args.corridor_m,
            drill_perception_stop_s: args.drill_perception_stop_s,
            drill_perception_offset,
            ..Default::default()
        }),
        clock: args.clock,
    };
    match session::run(request) {
        Ok(report) => {
            crate::outln!("{}", report.summary());
            report.exit_code
        }
        Err(e) => {
            crate::errln!("hitl run: {e}");
            e.exit_code()
        }
    }
}

/// Which arm the run drives: the embedded stub (with its faults), or the real one at `arm` once
/// the operator has confirmed the enclosure; stub-only flags with `--arm` are refused.
fn arm_target(args: &RunArgs, arm: Option<&str>) -> Result<ArmTarget, u8> {
    let Some(host) = arm else {
        return Ok(ArmTarget::Stub { faults: args.stub_faults.clone() });
    };
    if args.stub_start_q.is_some() {
        crate::errln!("hitl run: --stub-start-q only applies to the embedded stub, not to --arm");
        return Err(exit::BAD_INPUT);
    }
    if !args.stub_faults.is_empty() {
        crate::errln!("hitl run: --stub-fault only applies to the embedded stub, not to --arm");
        return Err(exit::BAD_INPUT);
    }
    if let Err(Refusal(code, m)) = args.labs.confirm_real_arm(host) {
        crate::errln!("hitl run: {m}");
        return Err(code);
    }
    Ok(ArmTarget::Remote { host: host.to_string() })
}
