//! The numbers of a run: counts, tracking error, loop lateness, pose error, events.

use crate::reader::Recording;
use crate::topics;
use hitl_hal::DOF;
use serde::Serialize;
use std::collections::BTreeMap;

/// Minimum, percentiles and maximum of a sample.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Spread {
    pub count: usize,
    pub mean: f64,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Spread {
    pub fn of(values: &[f64]) -> Option<Spread> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let pick = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Some(Spread {
            count: v.len(),
            mean: v.iter().sum::<f64>() / v.len() as f64,
            p50: pick(0.5),
            p99: pick(0.99),
            max: v[v.len() - 1],
        })
    }
}

#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Tracking {
    /// Measured reports compared with the setpoint in force when they were received.
    pub samples: usize,
    /// Per joint, radians.
    pub rms_rad: Vec<f64>,
    pub max_abs_rad: Vec<f64>,
    /// Largest over all joints, degrees.
    pub max_abs_deg: f64,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LoopTiming {
    pub ticks: usize,
    pub overruns: usize,
    /// Wake-up lateness, microseconds.
    pub wake_late_us: Option<Spread>,
    /// Tick work time, microseconds.
    pub tick_us: Option<Spread>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PoseError {
    /// Estimates matched to a ground truth of the same capture.
    pub pairs: usize,
    pub translation_mm: Option<Spread>,
    pub rotation_deg: Option<Spread>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventLine {
    /// Seconds from the run's start.
    pub t_s: f64,
    pub kind: String,
    pub detail: String,
}

/// The report's `summary.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Summary {
    /// The whole file was read: it ends with its footer and nothing in it is damaged.
    pub complete: bool,
    /// Why reading stopped early (a file cut short by a crash, damaged bytes).
    pub truncated: Option<String>,
    /// Captures read (`/camera/calibration` messages; every capture writes one).
    pub frames_read: u64,
    /// Captures the file holds, from its summary; null (unknown) for a file without one (cut
    /// short).
    pub frames_recorded: Option<u64>,
    pub duration_s: f64,
    pub topic_counts: BTreeMap<String, u64>,
    /// Telemetry dropped per topic, from the recorder's last counters.
    pub dropped: BTreeMap<String, u64>,
    pub frames_not_recorded: u64,
    pub setpoints_by_phase: BTreeMap<String, usize>,
    pub tracking: Option<Tracking>,
    pub timing: LoopTiming,
    /// Capture sync error (exposure minus trigger, `/camera/sync`), milliseconds.
    pub capture_sync_ms: Option<Spread>,
    pub pose_error: Option<PoseError>,
    pub events: Vec<EventLine>,
    pub trajectory_sha256: Option<String>,
    pub scale: Option<String>,
    /// The paper's calibrated pose metrics and the symmetry-aware ones (`hitl eval --json`'s
    /// keys), when the report was given a scorer (set by the report, not by [`summarize`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_metrics: Option<serde_json::Value>,
    /// `hitl run --closed-loop`: the relative-position error per capture, open and closed loop,
    /// as vision measured it (`crate::report::closed_loop`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub closed_loop_error: Option<crate::report::closed_loop::ClosedLoopError>,
    /// The captures on the report's contact sheet (set by the report, not by [`summarize`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact_sheet: Option<crate::report::contact::ContactSheet>,
}

/// Time origin of the run: earliest stamp of the loop's topics.
pub fn t0(rec: &Recording) -> u64 {
    [
        rec.setpoints.first().map(|m| m.t_ns),
        rec.states.first().map(|m| m.t_ns),
        rec.timing.first().map(|m| m.t_ns),
    ]
    .into_iter()
    .flatten()
    .min()
    .unwrap_or(0)
}

pub(crate) fn secs(t: u64, t0: u64) -> f64 {
    (t as f64 - t0 as f64) * 1e-9
}

/// Per measured report: (time s, per-joint error rad) against the latest setpoint at or
/// before it.
pub fn tracking_errors(rec: &Recording) -> Vec<(f64, [f64; DOF])> {
    let t0 = t0(rec);
    let sp = &rec.setpoints;
    rec.states
        .iter()
        .filter_map(|s| {
            let i = sp.partition_point(|p| p.t_ns <= s.t_ns);
            let p = sp.get(i.checked_sub(1)?)?;
            let e: [f64; DOF] = std::array::from_fn(|j| s.q[j] - p.q[j]);
            Some((secs(s.t_ns, t0), e))
        })
        .collect()
}

/// Per estimate with a ground truth of the same capture: (time s, translation m, rotation rad).
pub fn pose_errors(rec: &Recording) -> Vec<(f64, f64, f64)> {
    let t0 = t0(rec);
    rec.pose_estimate
        .iter()
        .filter_map(|e| {
            let i = rec.pose_gt.binary_search_by_key(&e.capture_ns, |g| g.capture_ns).ok()?;
            let g = &rec.pose_gt[i];
            let (dt, dr) = hitl_hal::pose::difference(&e.pose, &g.pose);
            Some((secs(e.capture_ns, t0), dt, dr))
        })
        .collect()
}

fn last_counters(rec: &Recording) -> (BTreeMap<String, u64>, u64) {
    let from_value = |v: &serde_json::Value| -> BTreeMap<String, u64> {
        v.as_object()
            .map(|o| o.iter().filter_map(|(k, n)| Some((k.clone(), n.as_u64()?))).collect())
            .unwrap_or_default()
    };
    if let Some(m) = rec.metadata.get(topics::META_RECORDER_STATS) {
        let dropped = m
            .get("dropped")
            .and_then(|s| serde_json::from_str::<serde_json::Value>(s).ok())
            .map(|v| from_value(&v))
            .unwrap_or_default();
        let fnr = m.get("frames_not_recorded").and_then(|s| s.parse().ok()).unwrap_or(0);
        return (dropped, fnr);
    }
    match rec.recorder_stats.last() {
        Some(v) => (from_value(&v["dropped"]), v["frames_not_recorded"].as_u64().unwrap_or(0)),
        None => (BTreeMap::new(), 0),
    }
}

pub fn summarize(rec: &Recording) -> Summary {
    let t0 = t0(rec);
    let t_end = [
        rec.setpoints.last().map(|m| m.t_ns),
        rec.states.last().map(|m| m.t_ns),
        rec.timing.last().map(|m| m.t_ns),
    ]
    .into_iter()
    .flatten()
    .max()
    .unwrap_or(t0);
    let mut by_phase = BTreeMap::new();
    for s in &rec.setpoints {
        let name = serde_json::to_value(s.phase)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default();
        *by_phase.entry(name).or_insert(0) += 1;
    }
    let errs = tracking_errors(rec);
    let tracking = (!errs.is_empty()).then(|| {
        let n = errs.len() as f64;
        let rms = (0..DOF)
            .map(|j| (errs.iter().map(|(_, e)| e[j] * e[j]).sum::<f64>() / n).sqrt())
            .collect();
        let max: Vec<f64> =
            (0..DOF).map(|j| errs.iter().map(|(_, e)| e[j].abs()).fold(0.0, f64::max)).collect();
        Tracking {
            samples: errs.len(),
            rms_rad: rms,
            max_abs_deg: max.iter().copied().fold(0.0, f64::max).to_degrees(),
            max_abs_rad: max,
        }
    });
    let late: Vec<f64> = rec.timing.iter().map(|t| t.wake_late_ns as f64 / 1e3).collect();
    let work: Vec<f64> = rec.timing.iter().map(|t| t.tick_ns as f64 / 1e3).collect();
    let pe = pose_errors(rec);
    let pose_error = (!rec.pose_estimate.is_empty()).then(|| PoseError {
        pairs: pe.len(),
        translation_mm: Spread::of(&pe.iter().map(|p| p.1 * 1e3).collect::<Vec<_>>()),
        rotation_deg: Spread::of(&pe.iter().map(|p| p.2.to_degrees()).collect::<Vec<_>>()),
    });
    let (dropped, frames_not_recorded) = last_counters(rec);
    let run = rec.metadata.get(topics::META_RUN);
    let end = rec.end.clone();
    Summary {
        complete: end.as_ref().is_some_and(|e| e.complete),
        frames_read: end.as_ref().map_or(0, |e| e.frames_read),
        frames_recorded: end.as_ref().and_then(|e| e.frames_recorded),
        truncated: end.and_then(|e| e.truncated),
        duration_s: secs(t_end, t0),
        topic_counts: rec.topic_counts.clone(),
        dropped,
        frames_not_recorded,
        setpoints_by_phase: by_phase,
        tracking,
        timing: LoopTiming {
            ticks: rec.timing.len(),
            overruns: rec.timing.iter().filter(|t| t.overrun).count(),
            wake_late_us: Spread::of(&late),
            tick_us: Spread::of(&work),
        },
        capture_sync_ms: Spread::of(
            &rec.capture_sync.iter().map(|s| s.sync_error_ns as f64 / 1e6).collect::<Vec<_>>(),
        ),
        pose_error,
        events: rec
            .events
            .iter()
            .map(|e| EventLine {
                t_s: secs(e.t_ns, t0),
                kind: e.kind.clone(),
                detail: e.detail.clone(),
            })
            .collect(),
        trajectory_sha256: run.and_then(|m| m.get("trajectory_sha256").cloned()),
        scale: run.and_then(|m| m.get("scale").cloned()),
        pose_metrics: None,
        closed_loop_error: crate::report::closed_loop::closed_loop_error(rec),
        contact_sheet: None,
    }
}
