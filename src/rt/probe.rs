//! A per-thread flag that says "this thread is inside the real-time loop".
//!
//! The loop raises it after its preparation and lowers it when the loop ends. A test's global
//! allocator reads it to count allocations made on the loop thread while the flag is up: the
//! proof that the tick allocates nothing. Reading it never allocates (const thread-local).

use std::cell::Cell;

thread_local! {
    static IN_RT_LOOP: Cell<bool> = const { Cell::new(false) };
}

/// Whether the calling thread is inside the real-time loop.
pub fn in_rt_loop() -> bool {
    IN_RT_LOOP.with(|f| f.get())
}

/// Raise the flag for the calling thread until the guard drops.
pub fn enter_rt_loop() -> RtLoopGuard {
    IN_RT_LOOP.with(|f| f.set(true));
    RtLoopGuard { _private: () }
}

/// Lowers the flag on drop.
pub struct RtLoopGuard {
    _private: (),
}

impl Drop for RtLoopGuard {
    fn drop(&mut self) {
        IN_RT_LOOP.with(|f| f.set(false));
    }
}

/// Lower the flag for the calling thread until the guard drops, then restore it: the simulated
/// world a lockstep pace advances between ticks is not the tick's work.
pub fn leave_rt_loop() -> RtLoopPause {
    RtLoopPause { was: IN_RT_LOOP.with(|f| f.replace(false)) }
}

/// Restores the flag on drop.
pub struct RtLoopPause {
    was: bool,
}

impl Drop for RtLoopPause {
    fn drop(&mut self) {
        IN_RT_LOOP.with(|f| f.set(self.was));
    }
}
