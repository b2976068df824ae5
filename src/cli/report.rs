//! `hitl report` (being built: see the issues).

use crate::exit;

#[derive(Debug, clap::Args)]
pub struct ReportArgs {}

pub fn run(_args: ReportArgs) -> u8 {
    eprintln!("hitl report: not built yet");
    exit::BAD_INPUT
}
