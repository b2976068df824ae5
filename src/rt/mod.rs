//! The real-time thread's machinery: a fixed period kept against absolute deadlines, the OS
//! settings that make wake-ups punctual, a lock-free latest-value slot, and an allocation probe.
//!
//! Nothing here knows about arms or trajectories; `control` builds the tick on top of it.

pub mod os;
pub mod period;
pub mod probe;
pub mod slot;

pub use os::{RtOptions, RtReport};
pub use period::{Periodic, Wake};
pub use slot::LatestSlot;
