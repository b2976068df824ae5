//! `hitl plan` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct PlanArgs {}

pub fn run(_args: PlanArgs) -> u8 {
    eprintln!("hitl plan: not built yet");
    exit::BAD_INPUT
}
