//! `hitl-drivers`: real devices behind the `hitl-hal` traits.
//!
//! - [`xarm`]: the xArm SDK's TCP protocol: a pure codec over byte slices, a TCP client on
//!   socket2 (command port 502) and the report stream reader;
//! - [`light`]: the studio light and trigger box on serial lines (DMX512 through an Enttec DMX USB
//!   Pro, and the project's trigger-box line protocol);
//! - [`orbbec`]: the Orbbec RGB-D camera through the Orbbec SDK v2 C API.

pub mod light;
pub mod orbbec;
pub mod xarm;
