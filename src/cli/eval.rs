//! `hitl eval` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct EvalArgs {}

pub fn run(_args: EvalArgs) -> u8 {
    eprintln!("hitl eval: not built yet");
    exit::BAD_INPUT
}
