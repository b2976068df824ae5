//! One module per subcommand: its flags (documented for `--help`) and what it does.

pub mod bench;
#[cfg(feature = "stub")]
pub mod calibrate;
pub mod campaign;
pub mod check;
pub mod device_flags;
pub mod eval;
#[cfg(feature = "export")]
pub mod export;
#[cfg(not(feature = "export"))]
#[path = "export_absent.rs"]
pub mod export;
pub mod park;
pub mod plan;
pub mod probe;
pub mod report;
pub mod reregister;
pub mod run;
#[cfg(feature = "stub")]
pub mod stub;
#[cfg(not(feature = "stub"))]
#[path = "stub_absent.rs"]
pub mod stub;
pub mod targets;
