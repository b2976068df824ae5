//! `hitl` as a library: the controller's parts, so that integration tests and benchmarks can drive
//! the same code the binary runs.
//!
//! - [`rt`]: the real-time thread: fixed period, absolute deadlines, OS real-time settings;
//! - [`control`]: the run (state machine, interlocks, the tick, approach and stop planning);
//! - [`closed_loop`]: `--closed-loop`: relative navigation, guidance and the corridor, off the loop;
//! - [`devices`]: absent ("none") devices and device choices;
//! - [`cli`]: one module per subcommand; [`exit`]: the contract's exit codes; [`console`]: output
//!   that a closed pipe cannot turn into a panic.

pub mod bench;
pub mod capture;
pub mod cli;
pub mod closed_loop;
pub mod console;
pub mod control;
pub mod devices;
pub mod exit;
#[cfg(feature = "export")]
pub mod export;
pub mod rt;
pub mod session;
pub mod telemetry;
