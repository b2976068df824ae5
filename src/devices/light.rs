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
        .block_on(spec.open(ctx.clock.clone()))
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

/// How much earlier than its scheduled tick a level change goes out when the lab configuration
/// gives no `[light] lead_ms`: the light path's mean latency, from the driver to the lamp.
///
/// - DMX (Enttec DMX USB Pro), 25 ms: the driver's task sees the new level within its 2 ms poll
///   (1 ms on average) and writes it at once, or after the 23 ms it keeps between frames when a
///   refresh has just gone (11.5 ms on average); the widget sends it in its next DMX packet, a
///   513-slot universe taking 22.7 ms on the wire at DMX512's 44 us a slot (11.3 ms on average
///   to the next packet, then 0.2 ms to the first channels), plus about 1 ms of USB. That is
///   25 ms on average and up to 49 ms. The fixture's own response (its dimmer curve and any
///   smoothing) comes on top and is not in this figure: measure it in the lab and set
///   `[light] lead_ms` (docs/lights.md).
/// - Trigger box, 2 ms: the box's task polls its slot every 1-2 ms, a USB full-speed frame is
///   1 ms, and the firmware sets the PWM duty at once (docs/trigger-box-protocol.md).
/// - The stub's simulated light and no light: 0 (the level is in the next render).
pub fn default_lead_ms(spec: &LightSpec) -> f64 {
    match spec {
        LightSpec::Dmx { .. } => 25.0,
        LightSpec::Trigger { .. } => 2.0,
        LightSpec::Sim | LightSpec::None => 0.0,
    }
}

/// The lead in ticks at `rate_hz`: `lead_ms` rounded to the nearest tick.
pub fn lead_ticks(lead_ms: f64, rate_hz: f64) -> u64 {
    let ticks = (lead_ms.max(0.0) * rate_hz / 1000.0).round();
    if ticks.is_finite() {
        ticks as u64
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lead_is_the_light_paths_latency_in_whole_ticks() {
        let dmx: LightSpec = "dmx:/dev/ttyUSB0".parse().expect("dmx");
        let tb: LightSpec = "trigger:/dev/ttyACM0".parse().expect("box");
        assert_eq!(lead_ticks(default_lead_ms(&dmx), 250.0), 6, "25 ms at 4 ms a tick");
        assert_eq!(lead_ticks(default_lead_ms(&tb), 250.0), 1, "2 ms rounds to one 4 ms tick");
        assert_eq!(lead_ticks(default_lead_ms(&LightSpec::Sim), 250.0), 0);
        assert_eq!(lead_ticks(f64::NAN, 250.0), 0);
        assert_eq!(lead_ticks(10.0, 100.0), 1);
    }
}
