//! The real-time thread's machinery: a fixed period kept against absolute deadlines (or, on a
//! simulated clock, whole periods in lockstep with the simulated world), the OS settings that
//! make wake-ups punctual, a lock-free latest-value slot, and an allocation probe.
//!
//! Nothing here knows about arms or trajectories; `control` builds the tick on top of it.

pub mod lockstep;
pub mod os;
pub mod period;
pub mod probe;
pub mod slot;

pub use lockstep::{Lockstep, World};
pub use os::{RtOptions, RtReport};
pub use period::{Pace, Periodic, Wake};
pub use slot::LatestSlot;
