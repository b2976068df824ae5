//! What the caller tells the recorder about the run: written once as the `run` metadata record.

use std::collections::BTreeMap;

/// The `run` metadata key naming the calibration the ground truth came from.
pub const CALIBRATION_KEY: &str = "calibration";

/// The `run` metadata record. Strings are written as given; `extra` adds any other keys.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunMetadata {
    /// The run's configuration (TOML or JSON text).
    pub config: String,
    /// SHA-256 of the trajectory file, hex.
    pub trajectory_sha256: String,
    /// The trajectory's `meta` (JSON text).
    pub trajectory_meta: String,
    /// The lab configuration (TOML text).
    pub lab_config: String,
    /// Versions: `hitl`, firmware, SDKs ... (written as one JSON object).
    pub versions: BTreeMap<String, String>,
    /// Scale of the lab relative to orbit (lab metres per real metre).
    pub scale: Option<f64>,
    /// Any further keys.
    pub extra: BTreeMap<String, String>,
    /// The trajectory's Sun phase schedule, when it has one.
    pub sun_phase: Option<SunPhaseTrack>,
    /// Where the ground truth's camera mount and target pose came from: `nominal` (hand-measured,
    /// also when empty) or the calibration's name (`hitl calibrate`'s provenance).
    pub calibration: String,
}

/// The trajectory's oriented Sun phase angle at its waypoints (`t` and `sun_phase_deg` of the
/// NPZ). Written as the `sun_phase` metadata record so the report can plot it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SunPhaseTrack {
    /// Seconds from the start of playback.
    pub t_s: Vec<f64>,
    /// Degrees, 0-360.
    pub sun_phase_deg: Vec<f64>,
}

impl SunPhaseTrack {
    /// At most `max` points, evenly picked (keeps the file and plots small).
    pub fn decimated(&self, max: usize) -> SunPhaseTrack {
        let n = self.t_s.len().min(self.sun_phase_deg.len());
        if n <= max || max < 2 {
            return SunPhaseTrack {
                t_s: self.t_s[..n].to_vec(),
                sun_phase_deg: self.sun_phase_deg[..n].to_vec(),
            };
        }
        let idx = (0..max).map(|k| k * (n - 1) / (max - 1));
        let (t, d) = idx.map(|i| (self.t_s[i], self.sun_phase_deg[i])).unzip();
        SunPhaseTrack { t_s: t, sun_phase_deg: d }
    }
}

impl RunMetadata {
    /// The `run` record as a string map.
    pub fn to_map(&self) -> BTreeMap<String, String> {
        let mut m = self.extra.clone();
        m.insert("config".into(), self.config.clone());
        m.insert("trajectory_sha256".into(), self.trajectory_sha256.clone());
        m.insert("trajectory_meta".into(), self.trajectory_meta.clone());
        m.insert("lab_config".into(), self.lab_config.clone());
        let calibration = if self.calibration.is_empty() { "nominal" } else { &self.calibration };
        m.insert(CALIBRATION_KEY.into(), calibration.to_string());
        m.insert("versions".into(), serde_json::to_string(&self.versions).unwrap_or_default());
        if let Some(s) = self.scale {
            m.insert("scale".into(), s.to_string());
        }
        m.entry("recorder".into())
            .or_insert_with(|| format!("hitl-record {}", env!("CARGO_PKG_VERSION")));
        m
    }
}
