//! The contract's exit codes (docs/architecture.md): scripts and tests outside the project rely on them.

/// Done.
pub const OK: u8 = 0;
/// Bad input or usage: unreadable or malformed files, bad flags, bad configuration.
pub const BAD_INPUT: u8 = 2;
/// The preflight refused the trajectory: the file is valid but the motion is unsafe.
pub const PREFLIGHT_REFUSED: u8 = 3;
/// An interlock stopped the run.
pub const INTERLOCK: u8 = 4;
/// A device or connection fault.
pub const DEVICE: u8 = 5;
/// The operator stopped the run (Ctrl-C) and the controlled stop completed.
pub const OPERATOR_STOP: u8 = 130;
