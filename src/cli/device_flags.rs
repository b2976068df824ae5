//! The device flags `run`, `calibrate` and `probe` share, typed at the CLI boundary, each written
//! once: which arm, camera, light and trigger box ([`DeviceFlags`]); the lab the controller
//! believes and the embedded stub's hidden one, read by one loader ([`LabFlags`]); the simulated
//! camera's stream, with one size parser ([`SimCameraFlags`]); and the one confirmation asked
//! before a real arm moves ([`LabFlags::confirm_real_arm`]).

use crate::devices::{CameraSpec, LightSpec, TriggerSpec};
use crate::exit;
use hitl_trajectories::lab::LabConfig;
use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;

/// A refusal at the CLI boundary: the exit code and the message (nothing has moved).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal(pub u8, pub String);

/// Which devices: the arm, the camera, the light and the trigger box.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct DeviceFlags {
    /// The real xArm's control box, HOST (`probe` also takes IP:PORT, e.g. a `hitl stub` on
    /// another port). `run` and `calibrate` without it: the embedded stub on loopback, nothing
    /// real moves; `probe` without it: no arm is queried.
    #[arg(long, value_name = "HOST")]
    pub arm: Option<String>,
    /// Camera: sim (the stub's rendered camera), orbbec (hardware-triggered by the trigger box's
    /// camera line: needs --trigger), orbbec:hardware (the same), orbbec:software (a model
    /// documented for software triggering, e.g. the Gemini 305), or none; an Orbbec choice may
    /// end in @SERIAL to name the camera (needed when several are connected). Default sim for
    /// `run` and `calibrate`; `probe` lists the cameras it sees and fails without one only when
    /// this is given (`--camera` alone means orbbec).
    #[arg(long, value_name = "sim|orbbec[:hardware|:software][@SERIAL]|none", num_args = 0..=1,
          default_missing_value = "orbbec")]
    pub camera: Option<CameraSpec>,
    /// Light (the Sun): sim, dmx:DEV[,addr=N][,16bit] (Enttec DMX USB Pro), trigger:DEV (the
    /// trigger box's light output; alone it is also the trigger, as --trigger), or none. Default
    /// sim for `run` and `calibrate`; `probe` opens only a light named here.
    #[arg(long, value_name = "sim|dmx:DEV|trigger:DEV|none")]
    pub light: Option<LightSpec>,
    /// Trigger box: trigger:DEV fires the camera's sync input at every capture and feeds the
    /// box's e-stop and door inputs to the interlocks, whatever drives the light (a DMX lab needs
    /// it to hardware-trigger its Orbbec); none (default) for a simulated or software-triggered
    /// camera. The same DEV as --light trigger:DEV is opened once and takes both roles.
    #[arg(long, value_name = "trigger:DEV|none")]
    pub trigger: Option<TriggerSpec>,
}

impl DeviceFlags {
    /// The camera of a run: as named, else the stub's.
    pub fn run_camera(&self) -> CameraSpec {
        self.camera.unwrap_or(CameraSpec::Sim)
    }

    /// The light of a run: as named, else the stub's.
    pub fn run_light(&self) -> LightSpec {
        self.light.clone().unwrap_or(LightSpec::Sim)
    }

    /// The trigger of a run: as named, else none.
    pub fn run_trigger(&self) -> TriggerSpec {
        self.trigger.clone().unwrap_or(TriggerSpec::None)
    }
}

/// The simulated camera's stream: intrinsics preset and size.
#[derive(Debug, Clone, clap::Args)]
pub struct SimCameraFlags {
    /// Simulated camera intrinsics: nfov, wfov (the paper's presets) or orbbec.
    #[arg(long, default_value = "orbbec", value_name = "nfov|wfov|orbbec")]
    pub camera_preset: String,
    /// Simulated camera resolution (intrinsics scaled to it), WIDTHxHEIGHT from 8 to 8192, e.g.
    /// 320x256. Default: the preset's own (`calibrate`: 640x400).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub camera_size: Option<(u32, u32)>,
}

/// `WIDTHxHEIGHT`, each a whole number from 8 to 8192: the one parser of an image size.
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or("expected WIDTHxHEIGHT, e.g. 320x256")?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|n| (8..=8192).contains(n));
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("'{s}': width and height must be whole numbers from 8 to 8192")),
    }
}

/// The lab the controller believes, the embedded stub's hidden one, and the operator's word.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LabFlags {
    /// Lab configuration (TOML, docs/lab-config.md). Defaults to the DreamSat-Bench enclosure.
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// SITL: the lab the embedded stub simulates (camera mount, target pose, board), while the
    /// controller keeps --config (how a calibration is tested against a hidden truth). Refused
    /// with --arm.
    #[arg(long, value_name = "TRUE.toml")]
    pub stub_config: Option<PathBuf>,
    /// Do not ask for confirmation before moving a real arm (the enclosure is known to be clear).
    #[arg(long)]
    pub yes: bool,
}

/// The labs of a run: the controller's, and the stub's when it differs.
#[derive(Debug, Clone)]
pub struct Labs {
    pub controller: LabConfig,
    pub stub: Option<LabConfig>,
}

impl LabFlags {
    /// Read both labs through the one validating loader (every number finite and in range,
    /// exit 2 naming the file and key), before any device opens.
    pub fn load(&self, arm: Option<&str>) -> Result<Labs, Refusal> {
        let read = |path: &PathBuf, flag: &str| {
            LabConfig::load(path).map_err(|e| Refusal(exit::BAD_INPUT, format!("{flag}: {e}")))
        };
        let controller = match &self.config {
            Some(p) => read(p, "--config")?,
            None => LabConfig::default(),
        };
        let stub = match (&self.stub_config, arm) {
            (None, _) => None,
            (Some(_), Some(_)) => {
                return Err(Refusal(
                    exit::BAD_INPUT,
                    "--stub-config only applies to the embedded stub, not to --arm".into(),
                ))
            }
            (Some(p), None) => Some(read(p, "--stub-config")?),
        };
        Ok(Labs { controller, stub })
    }

    /// Before a real arm at `host` moves: the operator confirms the enclosure is clear, unless
    /// `--yes` says so already. Refused (exit 2, nothing moved) when not confirmed or when there
    /// is no terminal to ask on.
    pub fn confirm_real_arm(&self, host: &str) -> Result<(), Refusal> {
        if self.yes {
            return Ok(());
        }
        if !std::io::stdin().is_terminal() {
            return Err(Refusal(
                exit::BAD_INPUT,
                format!(
                    "refusing to move the real arm at {host}: no terminal to confirm the \
                     enclosure is clear (pass --yes if it is); nothing moved"
                ),
            ));
        }
        crate::err!(
            "About to move the REAL arm at {host}. Is the enclosure clear and the door closed? \
             [y/N] "
        );
        let _ = std::io::stderr().flush();
        let mut line = String::new();
        let answered = std::io::stdin().lock().read_line(&mut line).is_ok();
        if answered && matches!(line.trim(), "y" | "Y" | "yes" | "YES") {
            Ok(())
        } else {
            Err(Refusal(
                exit::BAD_INPUT,
                format!("not confirmed that the enclosure around {host} is clear; nothing moved"),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_within_8_to_8192() {
        assert_eq!(parse_size("320x256"), Ok((320, 256)));
        assert_eq!(parse_size("1280X800"), Ok((1280, 800)));
        for bad in ["0x0", "7x8", "8x8193", "320", "axb", "-1x5", ""] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_stub_lab_is_refused_with_a_real_arm() {
        let flags = LabFlags { stub_config: Some("x.toml".into()), ..Default::default() };
        let e = flags.load(Some("10.0.0.5")).expect_err("refused");
        assert_eq!(e.0, exit::BAD_INPUT);
        assert!(e.1.contains("--stub-config"), "{}", e.1);
    }

    #[test]
    fn without_a_terminal_or_yes_a_real_arm_is_not_moved() {
        // The test harness's stdin is not a terminal.
        if std::io::stdin().is_terminal() {
            return;
        }
        let e = LabFlags::default().confirm_real_arm("10.0.0.5").expect_err("refused");
        assert!(e.1.contains("--yes") && e.1.contains("nothing moved"), "{}", e.1);
        assert_eq!(LabFlags { yes: true, ..Default::default() }.confirm_real_arm("h"), Ok(()));
    }
}
