//! What a recording holds, as the recorder counted it: the figures a run's summary and a failed
//! recording's error both carry.

use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// What a recording holds, as counted by the recorder.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RecordSummary {
    pub path: PathBuf,
    /// Messages written per topic.
    pub written: BTreeMap<String, u64>,
    /// Telemetry dropped per topic (queue full, oldest dropped).
    pub dropped: BTreeMap<String, u64>,
    /// Captures that could not be queued (each also a `capture-not-recorded` event).
    pub frames_not_recorded: u64,
    /// Message payload bytes written (before compression).
    pub bytes_in: u64,
    /// Size of the file on disk.
    pub file_bytes: u64,
    /// Seconds from spawn to close.
    pub elapsed_s: f64,
    /// Why the recorder stopped writing, if it did.
    pub failure: Option<String>,
}
