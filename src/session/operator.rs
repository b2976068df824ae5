//! The operator's Ctrl-C, and a hang-up: a controlled stop, never cut short by an impatient
//! second press or by a burst of hang-ups.

use crate::exit;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;

/// Ctrl-C asks for a controlled stop. An impatient second press must not cut that stop short
/// (the arm would be left on whatever setpoint came last), so it only says what is happening; a
/// third press abandons the stop and ends the process (exit 130), for a stop that cannot finish.
///
/// SIGHUP asks for the same controlled stop and never ends the process: it is what a campaign's
/// `hitl run` gets when the campaign dies (its parent-death signal, see
/// `cli::campaign::child`), and what a run started from a terminal gets when the terminal goes
/// (an SSH session dropped). The kernel sends a parent-death signal each time the child is handed
/// from a dying thread of its parent to the next, so one `kill -9` of a campaign can deliver
/// several: counted as presses they would abandon the stop.
pub(super) fn install_ctrlc(operator_stop: &Arc<AtomicBool>) {
    let flag = Arc::clone(operator_stop);
    let presses = AtomicU32::new(0);
    let _ = ctrlc::set_handler(move || {
        flag.store(true, Ordering::Release);
        match presses.fetch_add(1, Ordering::AcqRel) {
            0 => {}
            1 => crate::errln!(
                "hitl: controlled stop in progress; Ctrl-C once more abandons it and exits"
            ),
            _ => std::process::exit(i32::from(exit::OPERATOR_STOP)),
        }
    });
    install_hangup(operator_stop);
}

/// SIGHUP: the controlled stop, said once however many arrive.
fn install_hangup(operator_stop: &Arc<AtomicBool>) {
    use signal_hook::consts::SIGHUP;
    // The flag first, set in the handler itself: the stop is asked for even before the thread
    // below runs.
    if let Err(e) = signal_hook::flag::register(SIGHUP, Arc::clone(operator_stop)) {
        crate::errln!("hitl: cannot handle SIGHUP ({e}); a hang-up ends the run at once");
        return;
    }
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGHUP]) else { return };
    let spawned = std::thread::Builder::new().name("hitl-sighup".into()).spawn(move || {
        if signals.forever().next().is_some() {
            crate::errln!(
                "hitl: hang-up (SIGHUP: the campaign or terminal that started this run is \
                 gone): controlled stop"
            );
        }
    });
    drop(spawned);
}
