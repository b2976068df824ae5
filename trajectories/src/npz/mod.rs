//! Loading and writing NPZ trajectories (the schema in docs/architecture.md and `docs/npz-schema.md`).
//!
//! Layers, each with one concern:
//! - [`read`]: the zip container (`zip` crate) and each entry's `.npy` array (`npyz`), bounded by
//!   the entry's size from the zip directory and a per-entry cap ([`MAX_ENTRY_BYTES`]);
//! - [`guard`]: a bounds check in front of `npyz` so a header declaring a huge shape, a huge
//!   header or a deeply nested header is refused before anything is allocated;
//! - [`schema`]: keys, shapes, dtypes and value rules; errors name the key and waypoint index;
//! - [`write`]: what numpy's `savez` / `savez_compressed` write.
//!
//! Object (pickled) arrays are refused and never unpickled; integer and complex dtypes are
//! refused; float32 and float64, C and Fortran order, stored and deflated entries are accepted.
//! Unknown keys are warned about and never decoded.

pub mod error;
pub mod guard;
pub mod read;
pub mod schema;
pub mod write;

pub use error::{ColumnLabel, NpzError};
pub use read::MAX_ENTRY_BYTES;
pub use schema::validate;

use crate::trajectory::Trajectory;
use std::io::{BufReader, BufWriter, Cursor, Read, Seek};
use std::path::Path;

/// A loaded trajectory and what was worth saying about the file without refusing it (unknown
/// keys, float32 times, a `t` that does not start at 0, `meta` that is not JSON).
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    pub trajectory: Trajectory,
    pub warnings: Vec<String>,
}

/// How to read a file beyond the schema itself.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoadOptions {
    /// Waypoints per second of a file without `t` (waypoint `i` at `i / rate` seconds); `None`
    /// requires `t`. Refused for a file that has `t`.
    pub waypoint_rate_hz: Option<f64>,
}

/// Load and validate an NPZ trajectory file.
pub fn load(path: &Path) -> Result<Loaded, NpzError> {
    load_with(path, &LoadOptions::default())
}

/// Load and validate an NPZ trajectory file, with `options`.
pub fn load_with(path: &Path, options: &LoadOptions) -> Result<Loaded, NpzError> {
    let file = std::fs::File::open(path)
        .map_err(|source| NpzError::Read { path: path.display().to_string(), source })?;
    load_reader_with(BufReader::new(file), options)
}

/// Load and validate an NPZ trajectory held in memory.
pub fn load_bytes(bytes: &[u8]) -> Result<Loaded, NpzError> {
    load_reader(Cursor::new(bytes))
}

/// Load and validate an NPZ trajectory from any seekable reader.
pub fn load_reader<R: Read + Seek>(reader: R) -> Result<Loaded, NpzError> {
    load_reader_with(reader, &LoadOptions::default())
}

/// Load and validate an NPZ trajectory from any seekable reader, with `options`.
pub fn load_reader_with<R: Read + Seek>(
    reader: R,
    options: &LoadOptions,
) -> Result<Loaded, NpzError> {
    let mut warnings = Vec::new();
    let arrays = read::read_archive(reader, &mut warnings)?;
    let trajectory = schema::build(arrays, options.waypoint_rate_hz, &mut warnings)?;
    Ok(Loaded { trajectory, warnings })
}

/// Write `traj` as numpy's `savez` (`compressed = false`) or `savez_compressed` would. The
/// trajectory is validated first (hitl never writes a file it would refuse), written to a
/// temporary file beside `path`, then renamed over it, so a reader never sees half a file.
pub fn save(path: &Path, traj: &Trajectory, compressed: bool) -> Result<(), NpzError> {
    validate(traj)?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.partial-{}", std::process::id()));
    let werr = |p: &Path, source| NpzError::Write { path: p.display().to_string(), source };
    let result = (|| {
        let file = std::fs::File::create(&tmp).map_err(|e| werr(&tmp, e))?;
        let out = write::write_archive(BufWriter::new(file), traj, compressed)?;
        let file = out.into_inner().map_err(|e| werr(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| werr(&tmp, e))?;
        std::fs::rename(&tmp, path).map_err(|e| werr(path, e))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The NPZ bytes `save` would write.
pub fn to_bytes(traj: &Trajectory, compressed: bool) -> Result<Vec<u8>, NpzError> {
    validate(traj)?;
    Ok(write::write_archive(Cursor::new(Vec::new()), traj, compressed)?.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(n: usize) -> Trajectory {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.1).collect();
        Trajectory {
            qpos: t.iter().map(|x| [0.1 * x, 0.3, 0.0, 1.2, 0.0, 0.9, -x]).collect(),
            capture: Some((0..n).map(|i| i % 2 == 0).collect()),
            light: Some((0..n).map(|i| i as f32 / n as f32).collect()),
            u_rad: Some(t.iter().map(|x| x * 0.01).collect()),
            rel_pos_rtn_m: Some(t.iter().map(|x| [*x, -x, 2.0 * x]).collect()),
            cam_pose_base: Some(
                t.iter()
                    .map(|x| {
                        let mut m = [[0.0; 4]; 4];
                        for (r, row) in m.iter_mut().enumerate() {
                            for (c, v) in row.iter_mut().enumerate() {
                                *v = x + (r * 4 + c) as f64;
                            }
                        }
                        m
                    })
                    .collect(),
            ),
            sun_phase_deg: Some(t.iter().map(|x| 10.0 * x).collect()),
            meta: Some(r#"{"preset": "vbar-\u00e9", "scale": 0.5}"#.into()),
            t,
        }
    }

    #[test]
    fn round_trips_every_key_stored_and_compressed() {
        let traj = sample(5);
        for compressed in [false, true] {
            let bytes = to_bytes(&traj, compressed).expect("write");
            let back = load_bytes(&bytes).expect("read");
            assert_eq!(back.trajectory, traj);
            assert!(back.warnings.is_empty(), "{:?}", back.warnings);
        }
    }

    #[test]
    fn writes_the_same_bytes_twice() {
        let traj = sample(4);
        assert_eq!(to_bytes(&traj, true).expect("a"), to_bytes(&traj, true).expect("b"));
    }

    #[test]
    fn refuses_to_write_an_invalid_trajectory() {
        let mut traj = sample(3);
        traj.t[2] = traj.t[1];
        let e = to_bytes(&traj, false).expect_err("refused");
        assert!(matches!(e, NpzError::NotIncreasing { index: 2, .. }), "{e}");
    }

    #[test]
    fn garbage_is_not_a_zip() {
        let e = load_bytes(b"hello, this is not an npz").expect_err("refused");
        assert!(matches!(e, NpzError::NotZip { .. }), "{e}");
    }
}
