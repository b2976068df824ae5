//! `hitl bench` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct BenchArgs {}

pub fn run(_args: BenchArgs) -> u8 {
    eprintln!("hitl bench: not built yet");
    exit::BAD_INPUT
}
