//! `--light sim|dmx:DEV[,addr=N][,16bit]|trigger:DEV|none`: which light drives the Sun, and
//! `--trigger trigger:DEV|none`: which box fires the camera's sync input and feeds its e-stop and
//! door to the interlocks. The registry of the serial devices: parsing a choice ([`LightSpec`]'s
//! and [`TriggerSpec`]'s `FromStr`), naming it (`Display`) and opening it ([`LightSpec::open`],
//! [`TriggerSpec::open`]) are the one place a new kind of light or trigger is registered. The controller (src/devices) wraps whatever [`OpenedLight`] holds without naming
//! any driver; `sim` and `none` are not drivers and are handled there.

use std::fmt;
use std::str::FromStr;

use hitl_hal::{ErrorType, Inputs, Lifecycle, Light, MonotonicClock, Trigger};

use super::dmx::{DmxConfig, DmxLight, DmxResolution, UNIVERSE};
use super::fault::SerialError;
use super::trigger_box::{TriggerBox, TriggerBoxConfig};

/// The light chosen on the command line.
#[derive(Debug, Clone, PartialEq)]
pub enum LightSpec {
    /// The stub's simulated light.
    Sim,
    /// A DMX light on an Enttec DMX USB Pro at `port`.
    Dmx { port: String, config: DmxConfig },
    /// The light wired to the trigger box at `port`.
    Trigger { port: String },
    /// No light: level changes are ignored.
    None,
}

/// Why a `--light` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "--light {value:?}: {reason} (expected sim, none, dmx:DEV[,addr=N][,16bit] or trigger:DEV)"
)]
pub struct LightSpecError {
    pub value: String,
    pub reason: String,
}

impl FromStr for LightSpec {
    type Err = LightSpecError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |reason: String| LightSpecError { value: s.to_string(), reason };
        match s {
            "sim" => return Ok(LightSpec::Sim),
            "none" => return Ok(LightSpec::None),
            _ => {}
        }
        let (kind, rest) = s.split_once(':').ok_or_else(|| err("unknown light".into()))?;
        match kind {
            "dmx" => {
                let mut parts = rest.split(',');
                let port = parts.next().unwrap_or_default();
                if port.is_empty() {
                    return Err(err("missing serial device after dmx:".into()));
                }
                let mut config = DmxConfig::default();
                for opt in parts {
                    if opt == "16bit" {
                        config.resolution = DmxResolution::Bits16;
                    } else if opt == "8bit" {
                        config.resolution = DmxResolution::Bits8;
                    } else if let Some(v) = opt.strip_prefix("addr=") {
                        config.start_address = v
                            .parse::<u16>()
                            .ok()
                            .filter(|a| (1..=UNIVERSE).contains(a))
                            .ok_or_else(|| err(format!("DMX address {v:?} is not in 1..=512")))?;
                    } else {
                        return Err(err(format!(
                            "unknown DMX option {opt:?} (addr=N, 8bit, 16bit)"
                        )));
                    }
                }
                config.validate().map_err(|e| err(e.message().to_string()))?;
                Ok(LightSpec::Dmx { port: port.to_string(), config })
            }
            "trigger" => {
                if rest.is_empty() {
                    return Err(err("missing serial device after trigger:".into()));
                }
                Ok(LightSpec::Trigger { port: rest.to_string() })
            }
            other => Err(err(format!("unknown light kind {other:?}"))),
        }
    }
}

impl fmt::Display for LightSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LightSpec::Sim => f.write_str("sim"),
            LightSpec::None => f.write_str("none"),
            LightSpec::Trigger { port } => write!(f, "trigger:{port}"),
            LightSpec::Dmx { port, config } => {
                write!(f, "dmx:{port}")?;
                if config.start_address != 1 {
                    write!(f, ",addr={}", config.start_address)?;
                }
                if config.resolution == DmxResolution::Bits16 {
                    f.write_str(",16bit")?;
                }
                Ok(())
            }
        }
    }
}

/// A light driver as the controller holds it: level, lifecycle, movable to the real-time thread.
pub trait LightDriver: Light + Lifecycle + ErrorType<Error = SerialError> + Send {}
impl<T: Light + Lifecycle + ErrorType<Error = SerialError> + Send> LightDriver for T {}

/// Safety inputs a light device also reads (the trigger box's e-stop and door lines).
pub trait InputsDriver: Inputs + Lifecycle + ErrorType<Error = SerialError> + Send {}
impl<T: Inputs + Lifecycle + ErrorType<Error = SerialError> + Send> InputsDriver for T {}

/// Trigger lines a light device also fires (the trigger box's camera and strobe lines).
pub trait TriggerDriver: Trigger + Lifecycle + ErrorType<Error = SerialError> + Send {}
impl<T: Trigger + Lifecycle + ErrorType<Error = SerialError> + Send> TriggerDriver for T {}

/// A serial light, opened: the light itself, and the inputs and trigger lines the same device
/// provides, if any.
pub struct OpenedLight {
    /// Names the device and its port, for messages ("DMX light on /dev/ttyUSB0").
    pub name: String,
    pub light: Box<dyn LightDriver>,
    pub inputs: Option<Box<dyn InputsDriver>>,
    pub trigger: Option<Box<dyn TriggerDriver>>,
}

impl LightSpec {
    /// Open the serial light this names (`Ok(None)` for `sim` and `none`, which are not serial
    /// drivers). Must run inside the tokio runtime that will carry the drivers' I/O tasks for the
    /// whole run: the caller keeps that runtime alive until it has stopped the devices.
    pub async fn open(&self, clock: MonotonicClock) -> Result<Option<OpenedLight>, SerialError> {
        Ok(match self {
            LightSpec::Sim | LightSpec::None => None,
            LightSpec::Dmx { port, config } => Some(OpenedLight {
                name: format!("DMX light on {port}"),
                light: Box::new(DmxLight::open(port, *config).await?),
                inputs: None,
                trigger: None,
            }),
            LightSpec::Trigger { port } => {
                let tb = TriggerBox::open(port, TriggerBoxConfig::default(), clock).await?;
                Some(OpenedLight {
                    name: format!("trigger box on {port}"),
                    light: Box::new(tb.clone()),
                    inputs: Some(Box::new(tb.clone())),
                    trigger: Some(Box::new(tb)),
                })
            }
        })
    }
}

/// The trigger role chosen on the command line (`--trigger`): the device whose camera line fires
/// the camera's sync input and whose e-stop and door inputs feed the interlocks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TriggerSpec {
    /// The trigger box at `port` (docs/trigger-box.md).
    Box { port: String },
    /// No trigger device: a simulated or software-triggered camera, inputs from elsewhere.
    None,
}

/// Why a `--trigger` value was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--trigger {value:?}: {reason} (expected trigger:DEV or none)")]
pub struct TriggerSpecError {
    pub value: String,
    pub reason: String,
}

impl FromStr for TriggerSpec {
    type Err = TriggerSpecError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |reason: &str| TriggerSpecError { value: s.to_string(), reason: reason.into() };
        if s == "none" {
            return Ok(TriggerSpec::None);
        }
        match s.split_once(':') {
            Some(("trigger", "")) => Err(err("missing serial device after trigger:")),
            Some(("trigger", port)) => Ok(TriggerSpec::Box { port: port.to_string() }),
            Some(("dmx", _)) => Err(err("a DMX widget has no trigger line")),
            _ => Err(err("unknown trigger device")),
        }
    }
}

impl fmt::Display for TriggerSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TriggerSpec::Box { port } => write!(f, "trigger:{port}"),
            TriggerSpec::None => f.write_str("none"),
        }
    }
}

/// A trigger device, opened: its camera and strobe lines and the safety inputs it reads.
pub struct OpenedTrigger {
    /// Names the device and its port, for messages ("trigger box on /dev/ttyACM0").
    pub name: String,
    pub trigger: Box<dyn TriggerDriver>,
    pub inputs: Box<dyn InputsDriver>,
}

impl TriggerSpec {
    /// The serial port of the box this names, if any.
    pub fn port(&self) -> Option<&str> {
        match self {
            TriggerSpec::Box { port } => Some(port),
            TriggerSpec::None => None,
        }
    }

    /// Open the trigger device this names (`Ok(None)` for `none`). Runs inside the run's
    /// runtime, as [`LightSpec::open`] does.
    pub async fn open(&self, clock: MonotonicClock) -> Result<Option<OpenedTrigger>, SerialError> {
        Ok(match self {
            TriggerSpec::None => None,
            TriggerSpec::Box { port } => {
                let tb = TriggerBox::open(port, TriggerBoxConfig::default(), clock).await?;
                Some(OpenedTrigger {
                    name: format!("trigger box on {port}"),
                    trigger: Box::new(tb.clone()),
                    inputs: Box::new(tb),
                })
            }
        })
    }
}

#[cfg(test)]
mod trigger_spec_tests {
    use super::*;

    #[test]
    fn trigger_specs_parse_and_name_themselves() {
        let t: TriggerSpec = "trigger:/dev/ttyACM0".parse().expect("box");
        assert_eq!(t, TriggerSpec::Box { port: "/dev/ttyACM0".into() });
        assert_eq!(t.to_string(), "trigger:/dev/ttyACM0");
        assert_eq!(t.port(), Some("/dev/ttyACM0"));
        assert_eq!("none".parse::<TriggerSpec>(), Ok(TriggerSpec::None));
        for bad in ["trigger:", "dmx:/dev/ttyUSB0", "sim", "box", ""] {
            let e = bad.parse::<TriggerSpec>().expect_err(bad);
            assert!(e.to_string().contains("--trigger"), "{e}");
        }
    }
}
