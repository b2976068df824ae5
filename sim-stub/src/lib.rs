//! `hitl-sim-stub`: a MuJoCo-backed stub of the lab's arm, camera and light (SITL).
//!
//! It speaks the xArm SDK's protocol on loopback so that the controller, the official Python SDK
//! and CI cannot tell it from a control box for everything a servo stream uses.
//!
//! - [`plant`]: what the protocol server needs of a simulated arm (the [`plant::Plant`] trait);
//! - [`mjcf`], [`mujoco_plant`]: the lab scene written by the project and the MuJoCo plant;
//! - [`camera`]: the simulated RGB-D camera rendered from the flange camera;
//! - [`server`], [`faults`]: the xArm protocol server with a real box's state machine, and fault
//!   injection.

pub mod board;
pub mod camera;
pub mod faults;
pub mod mjcf;
pub mod mujoco_plant;
pub mod plant;
pub mod server;
pub mod target_look;

pub use faults::{Fault, FaultKind, SimInputs, SimInputsReader};
pub use server::bench::{bench_protocol, BenchError, BenchOptions};
pub use server::{Stub, StubConfig, StubError, StubHandle, ThreadStart};
