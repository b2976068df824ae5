//! `hitl check` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct CheckArgs {}

pub fn run(_args: CheckArgs) -> u8 {
    eprintln!("hitl check: not built yet");
    exit::BAD_INPUT
}
