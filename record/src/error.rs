//! Errors of recording and reading.

use crate::summary::RecordSummary;

/// Why the recorder could not start, write, or close.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("MCAP writer: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("encoding a message: {0}")]
    Encode(String),
    #[error("encoding JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("cannot start the recorder thread: {0}")]
    Spawn(std::io::Error),
    /// The recorder stopped writing during the run (disk full, file error). What was written
    /// before stays readable.
    #[error("recorder failed during the run: {reason}")]
    Failed { reason: String, summary: Box<RecordSummary> },
    #[error("the recorder thread panicked")]
    Panicked,
}

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: cannot read it: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{path}: not an MCAP recording: {reason}")]
    NotMcap { path: String, reason: String },
    /// An MCAP file with nothing to read: no readable chunk and no summary.
    #[error("{path}: nothing in it can be read: {reason}")]
    Unreadable { path: String, reason: String },
    #[error("{path}: topic {topic}: bad message: {reason}")]
    BadMessage { path: String, topic: String, reason: String },
}
