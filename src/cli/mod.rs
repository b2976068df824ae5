//! One module per subcommand: its flags (documented for `--help`) and what it does.

pub mod bench;
pub mod check;
pub mod eval;
pub mod plan;
pub mod report;
pub mod run;
pub mod stub;
