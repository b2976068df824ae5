//! The run: everything between "the operator asked to play this trajectory" and the exit code.
//!
//! - [`setpoint`]: a commanded joint state and the phases a setpoint can belong to;
//! - [`interlocks`]: what can trip a run, what each trip means (stop with motion, or hold) and
//!   which exit code it ends with;
//! - [`motion`]: jerk-limited moves planned with Ruckig (the approach and retreat legs, stops);
//! - [`planned_move`]: the approach and the retreat (and `hitl park`): a collision-free path,
//!   timed with Ruckig, every tick through the preflight;
//! - [`stop`]: the stop planner thread that turns a trip into a Ruckig stop without the tick
//!   allocating or waiting;
//! - [`stop_supervisor`]: after a tripped run, repeat the box's stop until a report shows it;
//! - [`telemetry`]: what the tick hands out (bounded lock-free, never blocking);
//! - [`tick`]: the real-time loop itself, short and readable top to bottom;
//! - [`session`]: connect, preflight, open devices, enable, approach, playback, settle, retreat,
//!   done.

pub mod interlocks;
pub mod motion;
pub mod planned_move;
pub mod progress;
pub mod session;
pub mod setpoint;
pub mod stop;
pub mod stop_supervisor;
pub mod telemetry;
pub mod tick;
