//! The xArm control box's TCP protocol (the official SDK's private Modbus-TCP framing).
//!
//! - [`codec`]: command frames as pure functions over byte slices (encode requests into
//!   caller-owned buffers, decode replies and their state bits);
//! - [`framing`]: a fixed-capacity accumulator that cuts a byte stream into frames;
//! - [`report`]: the report ports' frames (30000-30003), decode and encode;
//! - [`registers`], [`codes`]: register numbers, reply state bits, error and warning codes;
//! - [`client`]: the command connection ([`hitl_hal::Arm`]);
//! - [`reader`]: the report-stream reader ([`hitl_hal::ArmReports`]);
//! - [`error`]: [`XarmError`] and its [`hitl_hal::ErrorKind`].
//!
//! See `docs/xarm-protocol.md` for the byte layouts.

pub mod client;
pub mod codec;
pub mod codes;
pub mod error;
pub mod framing;
pub mod reader;
pub mod registers;
pub mod report;

pub use client::{ClientConfig, ServoReplies, XarmClient, COMMAND_PORT};
pub use error::XarmError;
pub use reader::{ReportConfig, ReportReader};
pub use report::ReportKind;
