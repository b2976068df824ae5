//! `hitl run` / `hitl record` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct RunArgs {}

pub fn run(_args: RunArgs, _record: bool) -> u8 {
    eprintln!("hitl run: not built yet");
    exit::BAD_INPUT
}
