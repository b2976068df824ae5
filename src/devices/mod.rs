//! Devices the controller assembles for a run, beyond the drivers: the "none" devices for runs
//! without a camera or light, and the parsing of `--camera` / `--light` choices.

pub mod any;
pub mod inputs;
pub mod none;
