//! The operator's Ctrl-C: a controlled stop, never cut short by an impatient second press.

use crate::exit;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;

/// Ctrl-C asks for a controlled stop. An impatient second press must not cut that stop short
/// (the arm would be left on whatever setpoint came last), so it only says what is happening; a
/// third press abandons the stop and ends the process (exit 130), for a stop that cannot finish.
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
}
