//! The capture path outside the tick: frames the camera delivered are matched to the arm state at
//! exposure and to ground truth, then handed to the recorder and the perception worker.
//!
//! - [`sink`]: the tick's telemetry sink for a run: recorder queues plus the intake queues;
//! - [`history`]: arm states kept by time, interpolated at an exposure;
//! - [`truth`]: the target's pose in the camera frame (OpenCV axes) from FK and the lab;
//! - [`intake`]: the thread that does the matching and hands frames on;
//! - [`mask`]: the target mask a frame gets (`--mask sim|rendered|none`), drawn there;
//! - [`sim_light`]: the stub's Sun level as a `Light`.

pub mod history;
pub mod intake;
pub mod mask;
#[cfg(feature = "stub")]
pub mod sim_light;
pub mod sink;
pub mod truth;
