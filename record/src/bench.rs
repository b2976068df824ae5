//! `hitl bench record`: sustained recording of camera-sized frames plus 250 Hz telemetry.
//!
//! Frames are synthetic but deterministic (the same integer formula as
//! scripts/bench_record_numpy.py, which times the paper's way on identical depth frames):
//! 1280x800 16UC1 depth (a round target in front of a wall, noise, holes) and 1280x720 rgb8.

use crate::compression::ChunkCompression;
use crate::msg::{ArmStateMsg, DepthImage, FrameRecord, Phase, Plane, SetpointMsg, TimingMsg};
use crate::recorder::{Recorder, RecorderConfig};
use crate::RunMetadata;
use hitl_hal::{Intrinsics, DOF};
use std::path::PathBuf;
use std::time::{Duration, Instant};

pub const DEPTH_W: u32 = 1280;
pub const DEPTH_H: u32 = 800;
pub const COLOR_W: u32 = 1280;
pub const COLOR_H: u32 = 720;

fn hash(x: u32, y: u32, k: u32) -> u32 {
    x.wrapping_mul(73_856_093) ^ y.wrapping_mul(19_349_663) ^ k.wrapping_mul(83_492_791)
}

/// Depth frame `k`, millimetres (same formula as the Python script).
pub fn synthetic_depth_mm(k: u32) -> Vec<u16> {
    let mut v = Vec::with_capacity((DEPTH_W * DEPTH_H) as usize);
    let cx = 640 + (k % 8) * 10;
    for y in 0..DEPTH_H {
        for x in 0..DEPTH_W {
            let h = hash(x, y, k);
            let dx = x.abs_diff(cx);
            let dy = y.abs_diff(400);
            let r2 = dx * dx + dy * dy;
            let base = if r2 < 250 * 250 { 900 + r2 / 400 } else { 2000 + y / 2 };
            let d = if h.is_multiple_of(97) { 0 } else { base + h % 9 };
            v.push(d as u16);
        }
    }
    v
}

/// Colour frame `k`, rgb8.
pub fn synthetic_color(k: u32) -> Vec<u8> {
    let mut v = Vec::with_capacity((COLOR_W * COLOR_H * 3) as usize);
    for y in 0..COLOR_H {
        for x in 0..COLOR_W {
            let h = hash(x, y, k);
            v.push(((x / 5 + k * 3) % 256) as u8);
            v.push(((y / 3) % 256) as u8);
            v.push((h % 64) as u8);
        }
    }
    v
}

/// CPU seconds this process has used (user + system), from /proc (Linux); `None` elsewhere.
/// On a shared machine, frames per CPU second compares writers fairly where wall time cannot.
pub fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    // USER_HZ is 100 on Linux for every architecture Rust targets here.
    Some((utime + stime) / 100.0)
}

/// One run of the benchmark.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub seconds: f64,
    /// Camera rate when paced; ignored in max-rate mode.
    pub fps: f64,
    pub telemetry_hz: f64,
    /// Push frames as fast as the recorder takes them (waiting while its queue is full).
    pub max_rate: bool,
    pub config: RecorderConfig,
    /// Keep the file here (else a temporary file, removed afterwards).
    pub keep: Option<PathBuf>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            seconds: 5.0,
            fps: 30.0,
            telemetry_hz: 250.0,
            max_rate: false,
            config: RecorderConfig::default(),
            keep: None,
        }
    }
}

fn frame(k: u32, depth: &[Vec<u16>], color: &[Vec<u8>], t_ns: u64) -> FrameRecord {
    let i = k as usize % depth.len();
    FrameRecord {
        tick: u64::from(k),
        capture_ns: t_ns,
        intrinsics: Intrinsics {
            width: DEPTH_W,
            height: DEPTH_H,
            fx: 900.0,
            fy: 900.0,
            cx: 640.0,
            cy: 400.0,
            distortion: Default::default(),
        },
        color: Some(Plane { width: COLOR_W, height: COLOR_H, data: color[i].clone().into() }),
        depth: Some(DepthImage::Millimetres(Plane {
            width: DEPTH_W,
            height: DEPTH_H,
            data: depth[i].clone().into(),
        })),
        mask: None,
        gt_pose: None,
        tf: None,
        trigger_ns: Some(t_ns),
        light_level: None,
    }
}

/// Run one benchmark; figures as JSON.
pub fn run_bench(opts: &BenchOptions) -> Result<serde_json::Value, crate::RecordError> {
    const DISTINCT: u32 = 4;
    let depth: Vec<Vec<u16>> = (0..DISTINCT).map(synthetic_depth_mm).collect();
    let color: Vec<Vec<u8>> = (0..DISTINCT).map(synthetic_color).collect();
    let path = opts.keep.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("hitl-bench-record-{}.mcap", std::process::id()))
    });
    let (handle, tel) = Recorder::spawn_with(&path, &RunMetadata::default(), opts.config)?;
    let cpu0 = process_cpu_s();
    let start = Instant::now();
    let period = Duration::from_secs_f64(1.0 / opts.telemetry_hz.max(1.0));
    let frame_period = Duration::from_secs_f64(1.0 / opts.fps.max(0.1));
    let run_for = Duration::from_secs_f64(opts.seconds.max(0.1));
    let (mut tick, mut frames_pushed) = (0u64, 0u32);
    let mut next_tick = start;
    let mut next_frame = start;
    let now_ns = |s: Instant| s.duration_since(start).as_nanos() as u64 + 1;
    while start.elapsed() < run_for {
        let now = Instant::now();
        if now >= next_tick {
            let t = now_ns(now);
            let q = [0.1 * (tick as f64 * 1e-3).sin(); DOF];
            tel.push_setpoint(&SetpointMsg {
                tick,
                t_ns: t,
                phase: Phase::Playback,
                q,
                qd: [0.0; DOF],
            });
            tel.push_state(&ArmStateMsg {
                t_ns: t,
                q,
                state: 1,
                mode: 1,
                error_code: 0,
                warn_code: 0,
            });
            tel.push_timing(&TimingMsg {
                tick,
                t_ns: t,
                wake_late_ns: now.duration_since(next_tick).as_nanos() as i64,
                tick_ns: 20_000,
                overrun: false,
            });
            tick += 1;
            next_tick += period;
        }
        let due = if opts.max_rate { tel.frame_queue_has_room() } else { now >= next_frame };
        if due {
            tel.push_frame(frame(frames_pushed, &depth, &color, now_ns(now)));
            frames_pushed += 1;
            next_frame += frame_period;
        }
        let wake = if opts.max_rate {
            next_tick.min(now + Duration::from_micros(200))
        } else {
            next_tick.min(next_frame)
        };
        if let Some(d) = wake.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
    let pushing_s = start.elapsed().as_secs_f64();
    let dropped = tel.total_drops();
    let not_recorded = tel.frames_not_recorded();
    let summary = handle.finish();
    let elapsed = start.elapsed().as_secs_f64();
    let cpu_s = process_cpu_s().zip(cpu0).map(|(b, a)| b - a);
    let summary = match summary {
        Ok(s) => s,
        Err(e) => {
            if opts.keep.is_none() {
                let _ = std::fs::remove_file(&path);
            }
            return Err(e);
        }
    };
    if opts.keep.is_none() {
        let _ = std::fs::remove_file(&path);
    }
    let frames = summary.written.get(crate::topics::DEPTH).copied().unwrap_or(0);
    let mb = 1e6;
    Ok(serde_json::json!({
        "mode": if opts.max_rate { "max-rate" } else { "paced" },
        "target_fps": if opts.max_rate { serde_json::Value::Null } else { opts.fps.into() },
        "seconds": elapsed,
        "frames_pushed": frames_pushed,
        "frames_written": frames,
        "frames_per_s": frames as f64 / elapsed,
        "frames_not_recorded": not_recorded,
        "telemetry_ticks": tick,
        "telemetry_dropped": dropped,
        "payload_mb_per_s": summary.bytes_in as f64 / mb / elapsed,
        "file_mb_per_s": summary.file_bytes as f64 / mb / elapsed,
        "file_mb": summary.file_bytes as f64 / mb,
        "compression_ratio": summary.bytes_in as f64 / (summary.file_bytes.max(1) as f64),
        "drain_after_push_s": elapsed - pushing_s,
        "cpu_s": cpu_s,
        "frames_per_cpu_s": cpu_s.filter(|c| *c > 0.0).map(|c| frames as f64 / c),
    }))
}

/// `hitl bench record`: a paced run at the camera rate (30 fps, 250 Hz telemetry) and a
/// max-rate run, `seconds` each, chunks compressed with `compression`. Errors are reported
/// inside the JSON.
pub fn bench_record(seconds: f64, compression: ChunkCompression) -> serde_json::Value {
    let config = RecorderConfig { compression, ..RecorderConfig::default() };
    let paced = BenchOptions { seconds, config, ..Default::default() };
    let max = BenchOptions { seconds, max_rate: true, config, ..Default::default() };
    let run = |o: &BenchOptions| {
        run_bench(o).unwrap_or_else(|e| serde_json::json!({"error": e.to_string()}))
    };
    let (p, m) = (run(&paced), run(&max));
    let cam = 30.0;
    serde_json::json!({
        "benchmark": "record",
        "frames": format!("depth {DEPTH_W}x{DEPTH_H} 16UC1 + color {COLOR_W}x{COLOR_H} rgb8"),
        "compression": compression.to_string(),
        "cores": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "paced": p,
        "max_rate": m,
        "max_rate_x_camera": m["frames_per_s"].as_f64().map(|f| f / cam),
        "numpy_side_by_side": "scripts/bench_record_numpy.py (savez_compressed per depth frame, same frames)",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The figures numpy computes for the same frames (scripts/bench_record_numpy.py): the
    /// side-by-side benchmark writes identical data.
    #[test]
    fn synthetic_depth_matches_the_numpy_script() {
        for (k, sum, centre, corner, holes) in [
            (0u32, 1_995_612_533u64, 904u16, 0u16, 10_602usize),
            (1, 1_995_646_436, 903, 2007, 10_566),
            (5, 1_995_189_896, 911, 2008, 10_816),
        ] {
            let d = synthetic_depth_mm(k);
            assert_eq!(d.iter().map(|v| u64::from(*v)).sum::<u64>(), sum, "frame {k}");
            assert_eq!(d[(400 * DEPTH_W + 640) as usize], centre);
            assert_eq!(d[0], corner);
            assert_eq!(d.iter().filter(|v| **v == 0).count(), holes);
        }
    }
}
