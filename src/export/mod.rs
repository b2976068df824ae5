//! Exports of recordings into the lab's other tools' formats: `hitl export lerobot` writes a
//! LeRobot v3.0 dataset (docs/lerobot-export.md).
//!
//! - [`episode`]: one recording read back as an episode: one frame per recorded capture, with the
//!   arm's joints, the commanded joints, poses, intrinsics and the run's orbit metadata;
//! - [`video`]: the image streams as video files (ffmpeg), depth quantised as LeRobot does;
//! - [`tables`]: the Parquet tables (frames, episodes, tasks) through Arrow;
//! - [`lerobot`]: the dataset as a whole: layout, `meta/info.json`, `meta/stats.json`, written
//!   into a temporary folder and renamed into place so nothing half-written is left.

pub mod episode;
pub mod lerobot;
pub mod tables;
pub mod video;

/// Why an export failed. [`ExportError::exit_code`] maps each to the contract's exit codes.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The input is not what an export needs (not an MCAP, no captures, mixed image sizes ...).
    #[error("{0}")]
    BadInput(String),
    /// The output folder cannot be used (exists, unwritable parent).
    #[error("{0}")]
    Output(String),
    /// ffmpeg is missing or failed: nothing is wrong with the input.
    #[error("{0}")]
    Encoder(String),
    /// Writing the dataset failed (disk full, permissions).
    #[error("{0}")]
    Io(String),
}

impl ExportError {
    /// Bad input and an unusable output folder are the user's to fix (2); an encoder or disk
    /// failure is the machine's (1).
    pub fn exit_code(&self) -> u8 {
        match self {
            ExportError::BadInput(_) | ExportError::Output(_) => crate::exit::BAD_INPUT,
            ExportError::Encoder(_) | ExportError::Io(_) => EXPORT_FAILED,
        }
    }
}

/// Exit code of an export that failed for a reason outside its input (ffmpeg, disk).
pub const EXPORT_FAILED: u8 = 1;

pub(crate) fn io_err(what: &str, path: &std::path::Path, e: impl std::fmt::Display) -> ExportError {
    ExportError::Io(format!("{what} {}: {e}", path.display()))
}
