//! The operator's view of a run while it plays: a progress bar on a terminal (tick, phase,
//! interlock status), plain lines otherwise. Reads [`LoopStatus`] atomics; never touches the loop.

use crate::control::tick::Program;
use crate::telemetry::LoopStatus;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Follow the loop until it is done.
pub fn follow(status: &LoopStatus, program: &Program, plain: bool) {
    let total = (program.approach.len() + program.playback.len() + program.retreat.len()) as u64;
    let bar = (!plain).then(|| {
        let bar = indicatif::ProgressBar::new(total.max(1));
        bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} [{bar:40}] tick {pos}/{len} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar
    });
    let mut last_line = std::time::Instant::now();
    let mut last_phase = None;
    while !status.done.load(Ordering::Acquire) {
        std::thread::sleep(Duration::from_millis(100));
        let tick = status.tick.load(Ordering::Relaxed);
        let phase = status.phase();
        let interlock = if status.tripped.load(Ordering::Relaxed) { "TRIPPED" } else { "armed" };
        let msg = format!(
            "{} | interlocks {interlock} | captures {}",
            phase.as_str(),
            status.captures.load(Ordering::Relaxed)
        );
        match &bar {
            Some(bar) => {
                bar.set_position(tick.min(total));
                bar.set_message(msg);
            }
            None => {
                if last_phase != Some(phase) || last_line.elapsed() >= Duration::from_secs(2) {
                    crate::errln!("tick {tick}/{total} {msg}");
                    last_line = std::time::Instant::now();
                    last_phase = Some(phase);
                }
            }
        }
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
}
