//! The plans committed under `trajectories/presets/`, each with the `hitl plan` command that
//! regenerates it (the same request). A test rebuilds them and compares bytes.

use super::{PlanRequest, Timing};
use crate::orbit::Preset;

/// One committed preset: file name (in `trajectories/presets/`), the regenerating command's
/// flags, and the request those flags make.
pub struct CommittedPreset {
    pub file: &'static str,
    pub flags: &'static str,
    pub request: PlanRequest,
}

/// Every committed preset, in README order.
pub fn committed() -> Vec<CommittedPreset> {
    vec![
        CommittedPreset {
            file: "flyaround-50m.npz",
            flags: "--preset flyaround --range-m 50 --duration-s 60",
            request: PlanRequest {
                preset: Preset::Flyaround,
                range_m: 50.0,
                timing: Timing::DurationS(60.0),
                ..PlanRequest::default()
            },
        },
        CommittedPreset {
            file: "flyaround-50m-25s.npz",
            flags: "--preset flyaround --range-m 50 --duration-s 25",
            request: PlanRequest {
                preset: Preset::Flyaround,
                range_m: 50.0,
                timing: Timing::DurationS(25.0),
                ..PlanRequest::default()
            },
        },
        CommittedPreset {
            file: "station-keeping-10m.npz",
            flags: "--preset station-keeping --range-m 10 --duration-s 20",
            request: PlanRequest {
                preset: Preset::StationKeeping,
                range_m: 10.0,
                timing: Timing::DurationS(20.0),
                ..PlanRequest::default()
            },
        },
    ]
}
