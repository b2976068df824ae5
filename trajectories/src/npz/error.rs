//! Why an NPZ trajectory was refused: one variant per problem, each naming the key (the array's
//! name in the archive) and, where it applies, the waypoint index.

/// Why an NPZ trajectory could not be read, or was refused, or could not be written.
#[derive(Debug, thiserror::Error)]
pub enum NpzError {
    /// The file could not be opened or read.
    #[error("cannot read {path}: {source}")]
    Read { path: String, source: std::io::Error },
    /// The file could not be written.
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    /// The bytes are not a zip archive (an NPZ is one), or its directory is damaged.
    #[error("not an NPZ file, or truncated: no readable zip archive ({detail})")]
    NotZip { detail: String },
    /// An entry's bytes could not be read in full: the file is truncated or corrupt.
    #[error("key '{key}': cannot read its bytes (truncated or corrupt file): {detail}")]
    Corrupt { key: String, detail: String },
    /// The entry is not a valid `.npy` array.
    #[error("key '{key}': not a valid .npy array: {detail}")]
    BadNpy { key: String, detail: String },
    /// The entry or its declared shape is larger than hitl accepts, or than the bytes it holds.
    #[error("key '{key}': {detail}")]
    TooLarge { key: String, detail: String },
    /// An object (pickled) array: refused, never unpickled.
    #[error("key '{key}': object (pickled) arrays are refused; write plain numeric arrays")]
    Pickled { key: String },
    /// A dtype the schema does not allow for this key (integers, complex, strings, ...).
    #[error("key '{key}': dtype {found} is refused; expected {expected}")]
    DType { key: String, found: String, expected: &'static str },
    /// The array has the wrong shape for its key.
    #[error("key '{key}': shape {found:?} is refused; expected {expected}")]
    Shape { key: String, found: Vec<u64>, expected: String },
    /// A required key is absent.
    #[error("key '{key}' is missing (required)")]
    Missing { key: &'static str },
    /// No `t` and no waypoint rate to derive it from.
    #[error(
        "key 't' is missing: the file gives no waypoint times. If its waypoints are sampled at a \
         fixed rate, give that rate with --waypoint-rate HZ (waypoint i plays at i / HZ seconds)"
    )]
    MissingTime,
    /// A waypoint rate given for a file that has its own `t`.
    #[error(
        "--waypoint-rate {rate} Hz was given, but the file has its own key 't': drop \
         --waypoint-rate (it is only for files without 't')"
    )]
    RateWithTime { rate: f64 },
    /// A waypoint rate that is not a positive finite number of waypoints per second.
    #[error(
        "--waypoint-rate {rate} Hz is refused: it must be a positive, finite rate up to {max} Hz"
    )]
    WaypointRate { rate: f64, max: f64 },
    /// Fewer than two waypoints.
    #[error("key 'qpos': {n} waypoint(s); a trajectory needs at least 2")]
    TooFew { n: usize },
    /// A per-waypoint array whose length differs from `qpos`'s.
    #[error("key '{key}': {len} waypoints, but 'qpos' has {expected}")]
    Length { key: String, len: usize, expected: usize },
    /// NaN or infinity.
    #[error("key '{key}': waypoint {index}{column}: value {value} is not finite")]
    NonFinite { key: String, index: usize, column: ColumnLabel, value: f64 },
    /// `t` does not increase strictly.
    #[error(
        "key 't': waypoint {index}: t = {value} s is not after waypoint {prev_index}'s {prev} s \
         (t must increase strictly)"
    )]
    NotIncreasing { index: usize, prev_index: usize, prev: f64, value: f64 },
    /// `t` starts before 0.
    #[error("key 't': waypoint 0: t = {value} s is negative (t counts seconds from 0)")]
    NegativeStart { value: f64 },
    /// A light level outside [0, 1].
    #[error("key 'light': waypoint {index}: level {value} is outside [0, 1]")]
    LightRange { index: usize, value: f64 },
    /// Writing: the zip or npy layer failed.
    #[error("cannot write key '{key}': {detail}")]
    Encode { key: String, detail: String },
}

/// Which column of a multi-column array a value sits in, for messages: `qpos` joints are named
/// `joint 1`..`joint 7` (1-based, as the lab says them), other arrays `column c` / `[r][c]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnLabel {
    /// A one-dimensional array.
    None,
    /// A joint of `qpos`, 0-based here and printed 1-based.
    Joint(usize),
    /// A column of a two-dimensional array.
    Column(usize),
    /// A cell of a 4x4 matrix.
    Cell(usize, usize),
}

impl std::fmt::Display for ColumnLabel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ColumnLabel::None => Ok(()),
            ColumnLabel::Joint(j) => write!(f, ", joint {}", j + 1),
            ColumnLabel::Column(c) => write!(f, ", column {c}"),
            ColumnLabel::Cell(r, c) => write!(f, ", cell [{r}][{c}]"),
        }
    }
}

impl NpzError {
    /// The key (array name) the error is about, when there is one.
    pub fn key(&self) -> Option<&str> {
        match self {
            NpzError::Corrupt { key, .. }
            | NpzError::BadNpy { key, .. }
            | NpzError::TooLarge { key, .. }
            | NpzError::Pickled { key }
            | NpzError::DType { key, .. }
            | NpzError::Shape { key, .. }
            | NpzError::Length { key, .. }
            | NpzError::NonFinite { key, .. }
            | NpzError::Encode { key, .. } => Some(key),
            NpzError::Missing { key } => Some(key),
            NpzError::TooFew { .. } => Some("qpos"),
            NpzError::NotIncreasing { .. }
            | NpzError::NegativeStart { .. }
            | NpzError::MissingTime
            | NpzError::RateWithTime { .. }
            | NpzError::WaypointRate { .. } => Some("t"),
            NpzError::LightRange { .. } => Some("light"),
            NpzError::Read { .. } | NpzError::Write { .. } | NpzError::NotZip { .. } => None,
        }
    }
}
