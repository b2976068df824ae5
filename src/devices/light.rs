//! Opening the `--light` choice. The serial lights are opened by their drivers' registry
//! (`hitl_drivers::light::LightSpec::open`); this module only wraps what it returns, and handles
//! the two choices that are not drivers (`sim`, `none`). A new kind of light touches its driver
//! file and its arms in drivers/src/light/spec.rs, never this file.

use super::any::{Kinds, RunLight, RunTrigger};
use super::inputs::RunInputs;
use super::none::{NoLight, NoTrigger};
use super::{DeviceError, OpenContext};
use hitl_drivers::light::LightSpec;

/// A light, with the inputs and trigger lines its device also provides.
pub struct OpenedLight {
    pub light: RunLight,
    pub inputs: RunInputs,
    pub trigger: RunTrigger,
}

/// Open the light `spec` names, on the run's runtime.
pub fn open_light(spec: &LightSpec, ctx: &OpenContext<'_>) -> Result<OpenedLight, DeviceError> {
    let none = || OpenedLight {
        light: RunLight { dev: Box::new(Kinds::new(NoLight)), name: "no light".into() },
        inputs: RunInputs::none(),
        trigger: RunTrigger { dev: Box::new(Kinds::new(NoTrigger)), name: "no trigger".into() },
    };
    match spec {
        LightSpec::None => return Ok(none()),
        #[cfg(feature = "stub")]
        LightSpec::Sim => {
            let sim = ctx.sim_needed("light")?;
            let mut opened = none();
            opened.light = RunLight {
                dev: Box::new(Kinds::new(crate::capture::sim_light::SimLight(sim.light.clone()))),
                name: "simulated light".into(),
            };
            return Ok(opened);
        }
        #[cfg(not(feature = "stub"))]
        LightSpec::Sim => {
            return Err(DeviceError::BadInput("--light sim needs the stub feature".into()))
        }
        _ => {}
    }
    let opened = ctx
        .runtime
        .block_on(spec.open(ctx.clock))
        .map_err(|e| DeviceError::Failed(format!("light {spec}: {e}")))?;
    let Some(serial) = opened else { return Ok(none()) };
    let mut out = none();
    out.light = RunLight { dev: Box::new(Kinds::new(serial.light)), name: serial.name.clone() };
    if let Some(inputs) = serial.inputs {
        out.inputs.add(serial.name.clone(), Box::new(Kinds::new(inputs)));
    }
    if let Some(trigger) = serial.trigger {
        out.trigger = RunTrigger { dev: Box::new(Kinds::new(trigger)), name: serial.name };
    }
    Ok(out)
}
