//! The state file that lets a crashed run be noticed: before the driver changes a camera's sync
//! configuration or settings it writes what it found there to
//! `<state dir>/orbbec/<serial>.sync`, and removes the file once that has been written back to
//! the camera. A file still there at the next open means a run ended without writing the camera's
//! configuration back (killed, crashed, the camera unplugged before close): the open reports it,
//! takes the configuration in the file as the one to write back (what the camera had before the
//! crashed run), and writes it back at its own close.
//!
//! Why a file and not a comparison with the factory default: a camera that the lab keeps in
//! another mode on purpose (a secondary in a chain, say) would be reported at every open, and a
//! crashed run's configuration could not be told from one another tool set. The driver also says
//! when it finds the camera waiting for triggers without any file (set by another tool, or by a
//! run before this file existed): it cannot know what to write back then, and leaves it.
//!
//! The state directory: `$HITL_STATE_DIR`, else `$XDG_STATE_HOME/hitl`, else
//! `$HOME/.local/state/hitl` (kept across reboots, as the camera keeps its configuration).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use super::backend::{SavedState, Setting};
use super::sync::SyncConfig;

/// Environment variable naming the state directory.
pub const STATE_DIR_ENV: &str = "HITL_STATE_DIR";

/// `$HITL_STATE_DIR`, else `$XDG_STATE_HOME/hitl`, else `$HOME/.local/state/hitl`; `None` when
/// none is set.
pub fn default_state_dir() -> Option<PathBuf> {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    var(STATE_DIR_ENV)
        .or_else(|| var("XDG_STATE_HOME").map(|d| d.join("hitl")))
        .or_else(|| var("HOME").map(|h| h.join(".local/state/hitl")))
}

/// The state file of the camera with `serial` under `dir`.
pub fn marker_path(dir: &Path, serial: &str) -> PathBuf {
    let name: String = serial
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' })
        .collect();
    let name = if name.is_empty() { "unknown".to_string() } else { name };
    dir.join("orbbec").join(format!("{name}.sync"))
}

/// A configuration a run saved and did not write back: found at open.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Leftover {
    /// The state file.
    pub path: PathBuf,
    /// What the camera had before that run changed it (written back at close).
    pub saved: SavedState,
    /// The process that wrote it, and when (seconds since the Unix epoch).
    pub pid: Option<u32>,
    pub written_unix_s: Option<u64>,
}

impl Leftover {
    /// One line for the operator.
    pub fn describe(&self) -> String {
        let by = match (self.pid, self.written_unix_s) {
            (Some(p), Some(t)) => format!(" (process {p}, {t} s after the Unix epoch)"),
            (Some(p), None) => format!(" (process {p})"),
            _ => String::new(),
        };
        format!(
            "a run ended without writing the camera's configuration back{by}: {} records what \
             it had before ({})",
            self.path.display(),
            self.saved.sync
        )
    }
}

/// Write `saved` for the camera at `path` (through a temporary file and a rename, so a crash
/// never leaves half a file).
pub fn write(path: &Path, serial: &str, saved: &SavedState) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let s = &saved.sync;
    let mut text = String::from(
        "# hitl: this Orbbec camera's configuration before hitl changed it; removed once written \
         back\n",
    );
    let now = SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let _ = writeln!(text, "serial={serial}\npid={}\nwritten_unix_s={now}", std::process::id());
    let _ = writeln!(
        text,
        "sync_mode={}\ndepth_delay_us={}\ncolor_delay_us={}\ntrigger_to_image_delay_us={}\n\
         trigger_out_enable={}\ntrigger_out_delay_us={}\nframes_per_trigger={}",
        s.mode,
        s.depth_delay_us,
        s.color_delay_us,
        s.trigger_to_image_delay_us,
        u8::from(s.trigger_out_enable),
        s.trigger_out_delay_us,
        s.frames_per_trigger
    );
    for (setting, value) in &saved.settings {
        let _ = writeln!(text, "{}={value}", setting.key());
    }
    let tmp = path.with_extension("sync.tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

/// The state file at `path`: `Ok(None)` when there is none; an error naming the file when it
/// cannot be read or is not one.
pub fn read(path: &Path) -> Result<Option<Leftover>, String> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
    };
    let bad = |what: &str| format!("{} is not a hitl state file ({what})", path.display());
    let get = |key: &str| {
        text.lines()
            .filter_map(|l| l.split_once('='))
            .find(|(k, _)| k.trim() == key)
            .map(|(_, v)| v.trim())
    };
    let int = |key: &str| -> Result<i32, String> {
        get(key).and_then(|v| v.parse().ok()).ok_or_else(|| bad(&format!("no {key}")))
    };
    let sync = SyncConfig {
        mode: get("sync_mode").and_then(|v| v.parse().ok()).ok_or_else(|| bad("no sync_mode"))?,
        depth_delay_us: int("depth_delay_us")?,
        color_delay_us: int("color_delay_us")?,
        trigger_to_image_delay_us: int("trigger_to_image_delay_us")?,
        trigger_out_enable: int("trigger_out_enable")? != 0,
        trigger_out_delay_us: int("trigger_out_delay_us")?,
        frames_per_trigger: int("frames_per_trigger")?,
    };
    let settings = Setting::ALL
        .iter()
        .filter_map(|s| get(s.key()).and_then(|v| v.parse().ok()).map(|v| (*s, v)))
        .collect();
    Ok(Some(Leftover {
        path: path.to_path_buf(),
        saved: SavedState { sync, settings },
        pid: get("pid").and_then(|v| v.parse().ok()),
        written_unix_s: get("written_unix_s").and_then(|v| v.parse().ok()),
    }))
}

/// Remove the state file (written back); a file already gone is fine.
pub fn remove(path: &Path) -> std::io::Result<()> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::orbbec::sync::MODE_FREE_RUN;

    #[test]
    fn a_saved_state_reads_back_as_written_and_goes_away() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = marker_path(dir.path(), "CP12/34");
        assert!(path.ends_with("orbbec/CP12_34.sync"), "{}", path.display());
        assert_eq!(read(&path), Ok(None));
        let saved = SavedState {
            sync: SyncConfig {
                mode: MODE_FREE_RUN,
                depth_delay_us: 1,
                color_delay_us: -2,
                trigger_to_image_delay_us: 3,
                trigger_out_enable: true,
                trigger_out_delay_us: 4,
                frames_per_trigger: 5,
            },
            settings: vec![(Setting::ExposureReference, 0)],
        };
        write(&path, "CP12/34", &saved).expect("write");
        let back = read(&path).expect("readable").expect("there");
        assert_eq!(back.saved, saved);
        assert_eq!(back.pid, Some(std::process::id()));
        remove(&path).expect("remove");
        remove(&path).expect("already gone is fine");
        assert_eq!(read(&path), Ok(None));
    }

    #[test]
    fn a_file_that_is_not_one_is_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = marker_path(dir.path(), "X");
        std::fs::create_dir_all(path.parent().expect("dir")).expect("mkdir");
        std::fs::write(&path, "hello").expect("write");
        let e = read(&path).expect_err("not a state file");
        assert!(e.contains("X.sync") && e.contains("no sync_mode"), "{e}");
    }
}
