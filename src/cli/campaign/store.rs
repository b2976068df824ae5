//! A campaign folder on disk: where each case's files live, atomic writes (a temporary file in the
//! same folder, then a rename, so a reader or a resumed campaign never sees half a file), and the
//! case result that marks a case as done.
//!
//! ```text
//! DIR/campaign.lock         held (flock) by the `hitl campaign run` playing the folder
//! DIR/manifest.toml          the manifest as last run
//! DIR/cases.json             index, id and definition of every case of that manifest
//! DIR/cases/<id>/case.lock   held by the run playing that case
//! DIR/cases/<id>/plan.npz    hitl plan's trajectory
//! DIR/cases/<id>/run.mcap    hitl run's recording (run-failed.mcap when the run failed)
//! DIR/cases/<id>/*.log       each stage's output
//! DIR/cases/<id>/eval.json   hitl eval --json of the estimator (with --mesh-faces when set)
//! DIR/cases/<id>/eval-gt.json hitl eval --json of the run's live estimates (ground-truth mesh)
//! DIR/cases/<id>/result.json the case's result: written last, it marks the case as done
//! DIR/results.csv, DIR/plots/ hitl campaign collect
//! ```

use super::manifest::Case;
use serde_json::Value;
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The most bytes read of a case's `result.json` (a few kilobytes when the campaign wrote it).
pub const MAX_RESULT_BYTES: u64 = 4 << 20;

/// The most bytes read of `cases.json` (about 600 bytes per case, at most
/// [`super::manifest::MAX_CASES`] cases).
pub const MAX_INDEX_BYTES: u64 = 256 << 20;

/// Read at most `cap` bytes of `path` (any kind of file: a manifest may come from a pipe); a file
/// with more is refused, not truncated.
pub fn read_capped(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    read_limited(File::open(path)?, cap)
}

fn read_limited(f: File, cap: u64) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    f.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(std::io::Error::other(format!("larger than {cap} bytes")));
    }
    Ok(bytes)
}

/// Read a file the campaign wrote: a regular file, not a symbolic link (opened without following
/// one, and without blocking on a FIFO), of at most `cap` bytes. Any other kind of file is
/// refused naming what it is; a missing one is `ErrorKind::NotFound`.
pub fn read_regular(path: &Path, cap: u64) -> std::io::Result<Vec<u8>> {
    let f = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| {
            if e.raw_os_error() == Some(libc::ELOOP) {
                std::io::Error::other("a symbolic link, not a file the campaign wrote")
            } else {
                e
            }
        })?;
    let meta = f.metadata()?;
    if !meta.is_file() {
        return Err(std::io::Error::other("not a regular file (a device, FIFO or folder)"));
    }
    if meta.len() > cap {
        return Err(std::io::Error::other(format!("{} bytes, more than {cap}", meta.len())));
    }
    read_limited(f, cap)
}

/// The lock file of a campaign folder.
pub fn folder_lock_path(out: &Path) -> PathBuf {
    out.join("campaign.lock")
}

/// Why a lock was not taken.
#[derive(Debug)]
pub enum LockError {
    /// Another process holds it.
    Busy,
    Io(std::io::Error),
}

/// Take an advisory lock (flock) on `path`, creating it: exclusive, or shared with other shared
/// holders. Held until the returned file is dropped or the process ends (a killed process
/// releases it at once); the descriptor is close-on-exec, so no child inherits it.
pub fn try_lock(path: &Path, exclusive: bool) -> Result<File, LockError> {
    let f = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(LockError::Io)?;
    let r = if exclusive { f.try_lock() } else { f.try_lock_shared() };
    match r {
        Ok(()) => Ok(f),
        Err(TryLockError::WouldBlock) => Err(LockError::Busy),
        Err(TryLockError::Error(e)) => Err(LockError::Io(e)),
    }
}

/// A temporary name next to `path` that no other process or thread uses: `NAME.PID-HOST-N.tmp.EXT`
/// (the extension kept, since some writers look at it).
pub fn temp_path(path: &Path) -> PathBuf {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default();
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let ext = path.extension().map(|s| format!(".{}", s.to_string_lossy())).unwrap_or_default();
    path.with_file_name(format!("{stem}.{}-{host}-{n}.tmp{ext}", std::process::id()))
}

/// Write `bytes` to `path` atomically: temporary file, fsync, rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    fn write_then_rename(tmp: &Path, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(tmp, path)
    }
    let tmp = temp_path(path);
    let result = write_then_rename(&tmp, path, bytes);
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Remove temporary files a killed campaign left in `dir` (their writers are gone or, if an
/// orphaned child still writes one, it writes into an unlinked file that no one reads).
pub fn remove_stale_temps(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().contains(".tmp") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// The folder of case `id` under campaign folder `out`.
pub fn case_dir(out: &Path, id: &str) -> PathBuf {
    out.join("cases").join(id)
}

/// The result file of a case.
pub fn result_path(out: &Path, id: &str) -> PathBuf {
    case_dir(out, id).join("result.json")
}

/// A case's recorded result, if it has one that parses (read as [`read_regular`] reads).
pub fn read_result(out: &Path, id: &str) -> Option<Value> {
    let bytes = read_regular(&result_path(out, id), MAX_RESULT_BYTES).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// Whether `case` is done: its result exists, says "ok", was made for the same definition and
/// passes `collect`'s checks (a corrupt result is played again).
pub fn is_done(out: &Path, case: &Case) -> bool {
    read_result(out, &case.id).is_some_and(|r| {
        super::collect::check_result(&r, &case.id, &case.definition()).is_ok_and(|s| s == "ok")
    })
}

/// The last `max` characters of a file (a failed stage's stderr), on a char boundary; only its
/// last `4 * max` bytes are read.
pub fn tail(path: &Path, max: usize) -> String {
    use std::io::{Seek, SeekFrom};
    let read = || -> std::io::Result<Vec<u8>> {
        let mut f = File::open(path)?;
        let keep = (4 * max) as u64;
        let len = f.metadata()?.len();
        f.seek(SeekFrom::Start(len.saturating_sub(keep)))?;
        let mut b = Vec::new();
        f.take(keep).read_to_end(&mut b)?;
        Ok(b)
    };
    let text = read().map(|b| String::from_utf8_lossy(&b).into_owned()).unwrap_or_default();
    let mut start = text.len().saturating_sub(max);
    while !text.is_char_boundary(start) {
        start += 1;
    }
    text[start..].trim().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_writes_leave_no_temporaries() {
        let d = tempfile::tempdir().expect("tempdir");
        let p = d.path().join("a.json");
        write_atomic(&p, b"{}").expect("write");
        write_atomic(&p, b"{\"x\":1}").expect("overwrite");
        assert_eq!(std::fs::read_to_string(&p).expect("read"), "{\"x\":1}");
        let names: Vec<String> = std::fs::read_dir(d.path())
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["a.json"]);
        let t = temp_path(&p);
        assert!(t.to_string_lossy().ends_with(".tmp.json"), "{}", t.display());
        std::fs::write(&t, "x").expect("temp");
        remove_stale_temps(d.path());
        assert!(!t.exists() && p.exists());
    }

    #[test]
    fn tail_keeps_the_end() {
        let d = tempfile::tempdir().expect("tempdir");
        let p = d.path().join("log");
        std::fs::write(&p, "début\nmiddle\nthe end\n").expect("write");
        assert_eq!(tail(&p, 8), "the end");
        assert_eq!(tail(&p, 1000), "début\nmiddle\nthe end");
        assert_eq!(tail(&d.path().join("none"), 10), "");
    }
}
