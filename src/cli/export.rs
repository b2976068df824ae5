//! `hitl export lerobot RUN.mcap... --out DIR`: recordings as a LeRobot v3.0 dataset
//! (docs/lerobot-export.md). Exit 0 done; 2 bad input (not an MCAP, no captures, mixed image
//! sizes, `--fps` out of range) or an `--out` the export may not write or replace (it exists, it
//! holds an input, it is a file or a folder that is not a dataset hitl wrote, it cannot be
//! written); 1 ffmpeg missing or failed, or the disk refused the dataset while it was written.

use crate::export::lerobot::{export, ExportRequest, MAX_FPS};
use std::path::PathBuf;

/// Export recordings into the lab's other tools' formats.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    #[command(subcommand)]
    pub format: ExportFormat,
}

#[derive(Debug, clap::Subcommand)]
pub enum ExportFormat {
    /// A LeRobot v3.0 dataset: one episode per recording, one frame per recorded capture;
    /// colour, depth (LeRobot's depth-map video) and mask as videos (needs ffmpeg).
    Lerobot(LerobotArgs),
}

#[derive(Debug, clap::Args)]
pub struct LerobotArgs {
    /// Recordings (MCAP), one episode each, in this order. All must have the same image size.
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
    /// The dataset folder to create (written beside it under a hidden name, then renamed).
    #[arg(long)]
    pub out: PathBuf,
    /// Frames per second of the dataset's time grid (timestamp = frame_index / fps), 1 to 1000;
    /// default: the captures' median rate, rounded. The true capture times are kept in
    /// `capture_time_s`.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_FPS)))]
    pub fps: Option<u32>,
    /// Task text of every episode (default: the trajectory's preset and range).
    #[arg(long)]
    pub task: Option<String>,
    /// Replace `--out` if it is a dataset hitl export wrote (never a file, a folder of other
    /// files, or one holding an input recording).
    #[arg(long)]
    pub force: bool,
    /// Print a summary as one JSON object.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: ExportArgs) -> u8 {
    match args.format {
        ExportFormat::Lerobot(a) => lerobot(a),
    }
}

fn lerobot(a: LerobotArgs) -> u8 {
    let req = ExportRequest {
        recordings: a.recordings,
        out: a.out,
        fps: a.fps,
        task: a.task,
        force: a.force,
    };
    match export(&req) {
        Ok(s) => {
            for r in s.recordings.iter().filter(|r| !r.complete) {
                crate::errln!(
                    "hitl export: warning: {} was not read to its end: {}; {}, only those are \
                     exported",
                    r.recording.display(),
                    r.read_stopped.as_deref().unwrap_or("it stopped early"),
                    hitl_record::reader::frames_text(r.frames_read, r.frames_recorded)
                );
            }
            if a.json {
                match serde_json::to_string(&s) {
                    Ok(j) => crate::outln!("{j}"),
                    Err(e) => crate::errln!("hitl export: {e}"),
                }
            } else {
                crate::outln!(
                    "{}: {} episodes, {} frames at {} fps, {}x{}, videos: {}",
                    s.out.display(),
                    s.episodes,
                    s.frames,
                    s.fps,
                    s.width,
                    s.height,
                    s.videos.join(", ")
                );
                let left: usize = s.incomplete_captures.iter().sum();
                if left > 0 {
                    crate::errln!(
                        "hitl export: {left} captures left out: one of their images was not recorded"
                    );
                }
            }
            crate::exit::OK
        }
        Err(e) => {
            crate::errln!("hitl export lerobot: {e}");
            e.exit_code()
        }
    }
}
