//! `hitl stub` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct StubArgs {}

pub fn run(_args: StubArgs) -> u8 {
    eprintln!("hitl stub: not built yet");
    exit::BAD_INPUT
}
