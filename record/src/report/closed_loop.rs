//! The closed loop's relative-position error, open and closed, from one `hitl run --closed-loop`
//! recording (docs/closed-loop.md, "In the report").
//!
//! Each `/closed_loop/gate` message of a capture with a pose carries what vision measured: the
//! chaser's deviation from its planned relative position that is not the controller's own
//! correction (`measured_lab_m`), and the camera correction in effect at that capture
//! (`correction_lab_m`). The first is the relative-position error the chaser would have had open
//! loop; the two added are the error it had closed loop. Both are as vision saw them at the
//! commanded joints: the stub's truth is not in the recording.

use crate::reader::Recording;
use crate::report::summary::{secs, t0, Spread};
use serde::Serialize;

/// The gate topic the figures are read from.
const GATE: &str = "/closed_loop/gate";

/// One capture's errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CaptureError {
    /// The capture's loop tick.
    pub tick: u64,
    /// When the navigator decided on it, seconds from the run's start.
    pub t_s: f64,
    /// Relative-position error without the correction (open loop), lab millimetres.
    pub open_mm: f64,
    /// With the correction in effect at the capture (closed loop), lab millimetres.
    pub closed_mm: f64,
    /// Whether the filter used the estimate (gate passed).
    pub used: bool,
}

/// The report's `closed_loop_error`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ClosedLoopError {
    pub open_mm: Option<Spread>,
    pub closed_mm: Option<Spread>,
    /// The last capture's errors (the end of the run).
    pub last: Option<CaptureError>,
    pub per_capture: Vec<CaptureError>,
}

fn vector(v: &serde_json::Value) -> Option<[f64; 3]> {
    let a = v.as_array().filter(|a| a.len() == 3)?;
    Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
}

fn norm(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Per capture with a measured deviation, in tick order; `None` for a recording without one (an
/// open-loop run, or one recorded before the gate carried the correction in effect).
pub fn closed_loop_error(rec: &Recording) -> Option<ClosedLoopError> {
    let t0 = t0(rec);
    let mut per_capture: Vec<CaptureError> = rec
        .closed_loop
        .iter()
        .filter(|(topic, _, _)| topic == GATE)
        .filter_map(|(_, t_ns, g)| {
            let measured = vector(&g["measured_lab_m"])?;
            let correction = vector(&g["correction_lab_m"])?;
            let closed = std::array::from_fn(|i| measured[i] + correction[i]);
            Some(CaptureError {
                tick: g["tick"].as_u64()?,
                t_s: secs(*t_ns, t0),
                open_mm: norm(measured) * 1e3,
                closed_mm: norm(closed) * 1e3,
                used: g["used"] == true,
            })
        })
        .collect();
    if per_capture.is_empty() {
        return None;
    }
    per_capture.sort_by_key(|c| c.tick);
    let of =
        |f: fn(&CaptureError) -> f64| Spread::of(&per_capture.iter().map(f).collect::<Vec<_>>());
    Some(ClosedLoopError {
        open_mm: of(|c| c.open_mm),
        closed_mm: of(|c| c.closed_mm),
        last: per_capture.last().copied(),
        per_capture,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn gate(
        tick: u64,
        measured: [f64; 3],
        correction: [f64; 3],
    ) -> (String, u64, serde_json::Value) {
        let g = json!({ "tick": tick, "used": true, "reason": "accepted",
                        "measured_lab_m": measured, "correction_lab_m": correction });
        (GATE.to_string(), tick * 4_000_000, g)
    }

    #[test]
    fn open_is_the_measured_deviation_and_closed_adds_the_correction_in_effect() {
        let mut rec = Recording::default();
        rec.closed_loop.push(gate(20, [-0.005, 0.0, 0.0], [0.003, 0.0, 0.0]));
        rec.closed_loop.push(gate(10, [-0.005, 0.0, 0.0], [0.0, 0.0, 0.0]));
        rec.closed_loop.push(("/closed_loop/filter".into(), 0, json!({ "tick": 5 })));
        // A lost estimate has no measurement: not a capture of the figure.
        rec.closed_loop.push((GATE.into(), 0, json!({ "tick": 15, "used": false })));
        let e = closed_loop_error(&rec).expect("figures");
        assert_eq!(e.per_capture.iter().map(|c| c.tick).collect::<Vec<_>>(), [10, 20]);
        assert!((e.per_capture[0].open_mm - 5.0).abs() < 1e-9);
        assert!((e.per_capture[0].closed_mm - 5.0).abs() < 1e-9);
        let last = e.last.expect("last");
        assert!((last.open_mm - 5.0).abs() < 1e-9 && (last.closed_mm - 2.0).abs() < 1e-9);
        assert!((e.closed_mm.expect("spread").mean - 3.5).abs() < 1e-9);
        assert!(closed_loop_error(&Recording::default()).is_none());
    }
}
