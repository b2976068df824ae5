//! A campaign folder on disk: where each case's files live, atomic writes (a temporary file in the
//! same folder, then a rename, so a reader or a resumed campaign never sees half a file), and the
//! case result that marks a case as done.
//!
//! ```text
//! DIR/manifest.toml          the manifest as last run
//! DIR/cases.json             index, id and definition of every case of that manifest
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
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

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

/// A case's recorded result, if it has one that parses.
pub fn read_result(out: &Path, id: &str) -> Option<Value> {
    let text = std::fs::read_to_string(result_path(out, id)).ok()?;
    serde_json::from_str(&text).ok()
}

/// Whether `case` is done: its result exists, says "ok", and was made for the same definition.
pub fn is_done(out: &Path, case: &Case) -> bool {
    read_result(out, &case.id).is_some_and(|r| {
        r.get("status").and_then(Value::as_str) == Some("ok")
            && r.get("definition") == Some(&case.definition())
    })
}

/// The last `max` characters of a file (a failed stage's stderr), on a char boundary.
pub fn tail(path: &Path, max: usize) -> String {
    let text = std::fs::read(path).map(|b| String::from_utf8_lossy(&b).into_owned());
    let text = text.unwrap_or_default();
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
