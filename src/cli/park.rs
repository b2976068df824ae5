//! `hitl park`: bring the arm to the lab's rest pose (`[arm] rest_q`) along a planned path around
//! the target, its tripod, the light and the walls, every tick preflighted, with every interlock
//! armed: the way back after a stopped run, or before the first one. Without `--arm` the embedded
//! stub; with `--arm HOST` a real arm, after the same confirmation as `hitl run`. Recorded as the
//! phase `retreat` when `--record` is given. Exit codes as `hitl run`'s: 0 parked, 2 bad input, 3
//! no safe path (the message names the obstacle in the way), 4 interlock, 5 device, 130 operator.

use crate::cli::device_flags::{DeviceFlags, LabFlags, Refusal};
use crate::devices::{CameraSpec, LightSpec, TriggerSpec};
use crate::exit;
use crate::rt::RtOptions;
use crate::session::{self, ArmTarget, RunRequest, TrajectorySource};
use hitl_perception::{BackendSpec, ReregisterPolicy};
use std::io::IsTerminal;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct ParkArgs {
    #[command(flatten)]
    pub devices: DeviceFlags,
    #[command(flatten)]
    pub labs: LabFlags,
    /// Control rate in Hz (50-250).
    #[arg(long, default_value_t = 250.0, value_name = "HZ")]
    pub rate: f64,
    /// Record the move to this MCAP file.
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// SCHED_FIFO priority of the loop thread, 1-99 (0: normal scheduler).
    #[arg(long, default_value_t = 80, value_name = "PRIO",
          value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// SITL: the embedded stub's arm powers up at these joints (7 comma-separated radians), e.g.
    /// where a stopped run left it. Refused with --arm.
    #[arg(long, value_name = "Q", value_parser = crate::cli::check::parse_joints,
          allow_hyphen_values = true)]
    pub stub_start_q: Option<hitl_hal::Joints>,
    /// Print plain progress lines even on a terminal.
    #[arg(long)]
    pub plain: bool,
}

pub fn run(args: ParkArgs) -> u8 {
    let arm = args.devices.arm.as_deref();
    let labs = match args.labs.load(arm) {
        Ok(labs) => labs,
        Err(Refusal(code, m)) => {
            crate::errln!("hitl park: {m}");
            return code;
        }
    };
    let target = match arm {
        None => ArmTarget::Stub { faults: Vec::new() },
        Some(_) if args.stub_start_q.is_some() => {
            crate::errln!(
                "hitl park: --stub-start-q only applies to the embedded stub, not to --arm"
            );
            return exit::BAD_INPUT;
        }
        Some(host) => {
            if let Err(Refusal(code, m)) = args.labs.confirm_real_arm(host) {
                crate::errln!("hitl park: {m}");
                return code;
            }
            ArmTarget::Remote { host: host.to_string() }
        }
    };
    let request = RunRequest {
        trajectory: TrajectorySource::Park,
        lab: labs.controller,
        rate_hz: args.rate,
        speed_scale: 1.0,
        target,
        record: args.record,
        record_compression: hitl_record::RecorderConfig::default().compression,
        // Parking captures nothing; a light or trigger box named is opened (the box's e-stop and
        // door inputs guard the move).
        camera: args.devices.camera.unwrap_or(CameraSpec::None),
        light: args.devices.light.clone().unwrap_or(LightSpec::None),
        trigger: args.devices.trigger.clone().unwrap_or(TriggerSpec::None),
        perception: BackendSpec::None,
        reregister: ReregisterPolicy::default(),
        mask: crate::capture::mask::MaskSource::None,
        mask_margin_px: 0,
        camera_preset: "orbbec".into(),
        camera_size: None,
        target_model: "asymmetric".into(),
        stub_lab: labs.stub,
        depth_model: Default::default(),
        rt: RtOptions::with_priority(args.rt_priority),
        retreat: true,
        stub_start_q: args.stub_start_q,
        plain_progress: args.plain || !std::io::stderr().is_terminal(),
        live: None,
        closed_loop: None,
        clock: session::ClockChoice::Realtime,
    };
    match session::run(request) {
        Ok(report) => {
            crate::outln!("{}", report.summary());
            report.exit_code
        }
        Err(e) => {
            crate::errln!("hitl park: {e}");
            if e.exit_code() == exit::PREFLIGHT_REFUSED {
                crate::errln!(
                    "hitl park: the arm is where it was; move it clear by hand (or with the \
                     control box's own tools) and park again"
                );
            }
            e.exit_code()
        }
    }
}
