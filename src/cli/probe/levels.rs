//! `hitl probe --light DEV --test-levels`: step the light through a few levels, holding each,
//! so the operator sees (or meters) it follow; the driver's health is checked after every step.
//! Says how early a run sends level changes to this kind of light (`[light] lead_ms`).

use crate::devices::light::default_lead_ms;
use crate::devices::LightSpec;
use crate::outln;
use hitl_hal::{Lifecycle as _, Light as _, MonotonicClock};
use std::time::{Duration, Instant};

/// The levels stepped through, in order (ending dark).
pub const LEVELS: [f32; 6] = [0.0, 0.25, 0.5, 0.75, 1.0, 0.0];
/// How long each level is held.
pub const HOLD: Duration = Duration::from_millis(400);

pub(super) fn test_levels(spec: &LightSpec) -> Result<(), String> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the I/O runtime: {e}"))?;
    let opened = rt.block_on(spec.open(MonotonicClock::new())).map_err(|e| e.to_string())?;
    let Some(mut opened) = opened else {
        outln!("light {spec}: no levels to step (not a serial device)");
        return Ok(());
    };
    outln!(
        "light {spec}: stepping through {} levels, {} ms each; a run sends level changes {} ms \
         early to this kind of light unless [light] lead_ms says otherwise",
        LEVELS.len(),
        HOLD.as_millis(),
        default_lead_ms(spec)
    );
    let start = Instant::now();
    let stepped = (|| {
        for level in LEVELS {
            let at = start.elapsed();
            opened.light.set_level(level).map_err(|e| format!("level {level}: {e}"))?;
            outln!("  level {level:.2} at +{} ms", at.as_millis());
            std::thread::sleep(HOLD);
            opened.light.health().map_err(|e| format!("after level {level}: {e}"))?;
        }
        Ok::<(), String>(())
    })();
    let stopped = opened.light.stop().map_err(|e| format!("stopping: {e}"));
    drop(opened);
    drop(rt);
    stepped?;
    stopped?;
    outln!("  light {spec}: followed every step (ends dark)");
    Ok(())
}
