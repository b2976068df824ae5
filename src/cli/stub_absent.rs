//! `hitl stub` in a build without the `stub` feature (no MuJoCo): says so and exits 2.

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct StubArgs {
    /// Ignored: this build has no stub.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    pub rest: Vec<String>,
}

pub fn run(_args: StubArgs) -> u8 {
    crate::errln!("hitl stub: this build has no MuJoCo stub (built without the `stub` feature)");
    exit::BAD_INPUT
}
