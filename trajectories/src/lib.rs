//! `hitl-trajectories`: everything about a trajectory before it reaches the loop.
//!
//! - [`trajectory`]: the typed trajectory of the NPZ schema;
//! - [`npz`]: loading and writing it with a real NPY/NPZ library, with typed errors;
//! - [`timing`]: time parametrisation from waypoints to setpoints at the control rate;
//! - [`kinematics`]: xArm7 forward kinematics, joint limits and the link-capsule model;
//! - [`joint_table`]: the xArm7's joint-limit tables and which one an arm's serial number means;
//! - [`geometry`]: capsules, segment distances, clearances;
//! - [`lab`]: the lab configuration (enclosure, arm base, keep-outs, camera mount, limits);
//! - [`preflight`]: the `hitl check` rules;
//! - [`path`]: collision-free joint-space paths around the lab's obstacles (RRT-Connect);
//! - [`bench`]: the NPZ load and time-parametrisation benchmark;
//! - [`orbit`], [`ik`], [`planner`]: the orbital planner that writes NPZ presets.

pub mod bench;
pub mod geometry;
pub mod ik;
pub mod joint_table;
pub mod kinematics;
pub mod lab;
pub mod npz;
pub mod orbit;
pub mod path;
pub mod planner;
pub mod preflight;
pub mod timing;
pub mod trajectory;

pub use trajectory::Trajectory;
