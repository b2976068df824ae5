//! The recorder's health as the control loop sees it: one atomic, read lock-free every tick.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};

const RUNNING: u8 = 0;
const FAILED: u8 = 1;
const CLOSED: u8 = 2;

#[derive(Debug, Default)]
struct Inner {
    state: AtomicU8,
    /// Why it failed (read outside the tick only).
    reason: Mutex<Option<String>>,
}

/// Shared health flag of one recorder. Cloning shares it.
#[derive(Debug, Clone, Default)]
pub struct RecorderHealth {
    inner: Arc<Inner>,
}

impl RecorderHealth {
    /// True once the recorder could not write (disk full, file error): the interlock must trip.
    /// Lock-free, never blocks: safe to call from the tick.
    pub fn is_failed(&self) -> bool {
        self.inner.state.load(Ordering::Acquire) == FAILED
    }

    /// True once the file was closed cleanly.
    pub fn is_closed(&self) -> bool {
        self.inner.state.load(Ordering::Acquire) == CLOSED
    }

    /// The failure's description, if it failed (not for the tick: takes a lock).
    pub fn failure(&self) -> Option<String> {
        self.inner.reason.lock().ok().and_then(|r| r.clone())
    }

    pub(crate) fn set_failed(&self, reason: String) {
        if let Ok(mut r) = self.inner.reason.lock() {
            if r.is_none() {
                *r = Some(reason);
            }
        }
        self.inner.state.store(FAILED, Ordering::Release);
    }

    pub(crate) fn set_closed(&self) {
        let _ =
            self.inner.state.compare_exchange(RUNNING, CLOSED, Ordering::AcqRel, Ordering::Acquire);
    }
}
