//! Frames read back from a recording (`/camera/depth`, `/camera/mask`, `/camera/color`,
//! `/camera/calibration`) for re-running a backend offline (`hitl eval --backend`).
//!
//! Frames are assembled by capture timestamp and handed out one at a time in file order, so
//! memory stays bounded (at most `PENDING` captures are held while their images arrive).

use crate::{PerceptionError, PerceptionFrame};
use foxglove::messages as fg;
use hitl_hal::Intrinsics;
use hitl_record::reader::{decode_image, decode_intrinsics, depth_metres, packed_rows, visit};
use hitl_record::topics;
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::Path;

/// Captures held while waiting for their other images.
const PENDING: usize = 4;

#[derive(Default)]
struct Partial {
    depth: Option<(u32, u32, Vec<f32>)>,
    mask: Option<Vec<u8>>,
    color: Option<Vec<u8>>,
}

/// What a replay went through.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ReplaySummary {
    pub frames: usize,
    /// Captures skipped: no calibration yet, undecodable image, or sizes that disagree.
    pub skipped: usize,
    /// The file ended before its footer.
    pub truncated: bool,
}

fn ts(t: Option<fg::Timestamp>, log_time: u64) -> u64 {
    t.map(|t| t.total_nanos()).unwrap_or(log_time)
}

/// Calls `on_frame` for every capture that has depth and a calibration, in file order.
pub fn replay_frames(
    path: &Path,
    mut on_frame: impl FnMut(PerceptionFrame),
) -> Result<ReplaySummary, PerceptionError> {
    let mut pending: BTreeMap<u64, Partial> = BTreeMap::new();
    let mut calib: Option<Intrinsics> = None;
    let mut summary = ReplaySummary::default();
    let mut seq = 0u64;
    let mut flush = |t: u64, p: Partial, calib: &Option<Intrinsics>, s: &mut ReplaySummary| {
        let (Some(k), Some((w, h, depth))) = (calib, p.depth) else {
            s.skipped += 1;
            return;
        };
        if k.width != w || k.height != h {
            s.skipped += 1;
            return;
        }
        let n = (w * h) as usize;
        let frame = PerceptionFrame {
            timestamp_ns: t,
            seq,
            intrinsics: *k,
            color: p.color.filter(|c| c.len() == 3 * n).unwrap_or_default().into(),
            depth_m: depth.into(),
            mask: p.mask.filter(|m| m.len() == n).map(Into::into),
        };
        seq += 1;
        s.frames += 1;
        on_frame(frame);
    };
    let mut bad: Option<String> = None;
    let end = visit(
        path,
        |m| {
            let topic = m.topic;
            if topic == topics::CALIBRATION {
                match decode_intrinsics(m.data, m.log_time) {
                    Ok((_, k)) => calib = Some(k),
                    Err(e) => bad = Some(e.to_string()),
                }
                return if bad.is_some() {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                };
            }
            if topic != topics::DEPTH && topic != topics::MASK && topic != topics::COLOR {
                return ControlFlow::Continue(());
            }
            let Ok(img) = decode_image(m.data) else {
                summary.skipped += 1;
                return ControlFlow::Continue(());
            };
            let t = ts(img.timestamp, m.log_time);
            let entry = pending.entry(t).or_default();
            match topic {
                topics::DEPTH => {
                    entry.depth = depth_metres(&img).map(|d| (img.width, img.height, d))
                }
                topics::MASK => entry.mask = packed_rows(&img, 1),
                _ => entry.color = packed_rows(&img, 3),
            }
            while pending.len() > PENDING {
                if let Some((t0, p)) = pending.pop_first() {
                    flush(t0, p, &calib, &mut summary);
                }
            }
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .map_err(|e| PerceptionError::BadInput(e.to_string()))?;
    if let Some(b) = bad {
        return Err(PerceptionError::BadInput(format!("{}: {b}", path.display())));
    }
    while let Some((t0, p)) = pending.pop_first() {
        flush(t0, p, &calib, &mut summary);
    }
    summary.truncated = !end.complete;
    Ok(summary)
}
