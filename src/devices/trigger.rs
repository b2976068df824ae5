//! Opening the `--trigger` choice: the device whose camera line fires the camera's sync input and
//! whose e-stop and door inputs feed the interlocks. The trigger devices are opened by the
//! drivers' registry (`hitl_drivers::light::TriggerSpec::open`); this module decides which
//! connection holds the role:
//! - `--light trigger:DEV` alone: that box is light and trigger (as before `--trigger` existed);
//! - `--trigger trigger:DEV` with the same `--light trigger:DEV`: the one connection takes both
//!   roles (a serial port is opened once);
//! - `--trigger trigger:DEV` with another light (`dmx:DEV`, `sim`, `none`): the box is opened for
//!   its trigger lines and inputs; its light output stays at its safe level.

use super::any::{Kinds, RunTrigger};
use super::light::OpenedLight;
use super::{DeviceError, OpenContext};
use hitl_drivers::light::{LightSpec, TriggerSpec};

/// Give the trigger role to the device `trigger` names, next to the light already opened.
pub fn open_trigger(
    trigger: &TriggerSpec,
    light: &LightSpec,
    opened: &mut OpenedLight,
    ctx: &OpenContext<'_>,
) -> Result<(), DeviceError> {
    let Some(port) = trigger.port() else { return Ok(()) };
    if matches!(light, LightSpec::Trigger { port: p } if p == port) {
        return Ok(());
    }
    let Some(t) = ctx
        .runtime
        .block_on(trigger.open(ctx.clock.clone()))
        .map_err(|e| DeviceError::Failed(format!("trigger {trigger}: {e}")))?
    else {
        return Ok(());
    };
    opened.inputs.add(t.name.clone(), Box::new(Kinds::new(t.inputs)));
    opened.trigger = RunTrigger { dev: Box::new(Kinds::new(t.trigger)), name: t.name };
    Ok(())
}
