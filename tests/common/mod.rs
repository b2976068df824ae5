//! Helpers shared by the end-to-end tests: running the `hitl` binary, and the lab they play in.
#![allow(dead_code)] // each test binary uses its own subset

use std::process::{Command, Output, Stdio};

/// Runs `hitl ARGS...` with no stdin and returns what it printed and its exit status.
pub fn hitl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hitl"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run hitl")
}

/// The default lab with a watchdog and deviation limit a shared VM's steal time cannot trip by
/// itself (the file says why). Tests about those interlocks keep the defaults.
pub const SHARED_VM_LAB: &str =
    concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/shared-vm-lab.toml");

/// The default lab with 400 ms silence limits, for the tests that silence the arm: what they
/// inject, not the host's scheduling, trips (the file says why).
pub const SILENCE_LAB: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/silence-lab.toml");
