//! The loop and what it acts with: the tick, the interlocks, and the moves it plays. Nothing here
//! opens a device, names a driver or the stub, or allocates on the tick; the session
//! (`crate::session`) prepares a run and hands this module its program and devices.
//!
//! - [`correction`]: the closed loop's one step in the tick: a prepared, checked joint offset added
//!   to the planned setpoint (`--closed-loop`, docs/closed-loop.md);
//! - [`interlocks`]: what each trip means (stop with motion, or hold) and which exit code it ends
//!   with (the trip itself, a fact, is `crate::telemetry::Trip`);
//! - [`motion`]: jerk-limited moves planned with Ruckig (the approach and retreat legs, stops);
//! - [`planned_move`]: the approach and the retreat (and `hitl park`): a collision-free path,
//!   timed with Ruckig, every tick through the preflight;
//! - [`stop`]: the stop planner thread that turns a trip into a Ruckig stop without the tick
//!   allocating or waiting;
//! - [`stop_supervisor`]: after a tripped run, repeat the box's stop until a report shows it;
//! - [`tick`]: the real-time loop itself, short and readable top to bottom.
//!
//! A setpoint is a [`hitl_hal::JointState`] tagged with a [`hitl_hal::Phase`].

pub mod correction;
pub mod interlocks;
pub mod motion;
pub mod planned_move;
pub mod stop;
pub mod stop_supervisor;
pub mod tick;
