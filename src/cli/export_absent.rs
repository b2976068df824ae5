//! `hitl export` in a build without the `export` feature (`make demo`'s): says so and exits 2.

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// Ignored: this build has no exporter.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    pub rest: Vec<String>,
}

pub fn run(_args: ExportArgs) -> u8 {
    crate::errln!(
        "hitl export: this build has no exporter (built without the `export` feature, as `make \
         demo` builds); `cargo build --release` builds it"
    );
    exit::BAD_INPUT
}
