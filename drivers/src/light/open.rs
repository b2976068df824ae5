//! Opening the serial light a [`LightSpec`] names, as one [`Light`] type.

use hitl_hal::{ErrorType, Light, MonotonicClock};

use super::dmx::DmxLight;
use super::fault::SerialError;
use super::spec::LightSpec;
use super::trigger_box::{TriggerBox, TriggerBoxConfig};

/// A light on a serial port: DMX or the trigger box.
pub enum SerialLight {
    Dmx(DmxLight),
    /// The trigger box; clone it to use its `Trigger` and `Inputs` too.
    Trigger(TriggerBox),
}

impl SerialLight {
    /// Open the serial light `spec` names as this enum (for `hitl probe`, which asks each kind
    /// its own questions); `Ok(None)` for `sim`, `none` and kinds it does not know. A run opens
    /// lights through [`LightSpec::open`] instead. Must run inside a tokio runtime.
    pub async fn open(
        spec: &LightSpec,
        clock: MonotonicClock,
    ) -> Result<Option<Self>, SerialError> {
        Ok(match spec {
            LightSpec::Dmx { port, config } => {
                Some(SerialLight::Dmx(DmxLight::open(port, *config).await?))
            }
            LightSpec::Trigger { port } => Some(SerialLight::Trigger(
                TriggerBox::open(port, TriggerBoxConfig::default(), clock).await?,
            )),
            _ => None,
        })
    }
}

impl ErrorType for SerialLight {
    type Error = SerialError;
}

impl Light for SerialLight {
    fn set_level(&mut self, level: f32) -> Result<(), SerialError> {
        match self {
            SerialLight::Dmx(l) => l.set_level(level),
            SerialLight::Trigger(t) => t.set_level(level),
        }
    }

    fn strobe(&mut self, level: f32, duration_us: u32) -> Result<(), SerialError> {
        match self {
            SerialLight::Dmx(l) => l.strobe(level, duration_us),
            SerialLight::Trigger(t) => t.strobe(level, duration_us),
        }
    }
}
