//! `hitl probe --camera`: every Orbbec camera the SDK sees with what commissioning needs (serial,
//! firmware and whether it is new enough for the sync voltage setting, profiles, intrinsics and
//! distortion of each size, the sync configuration found on it, a crashed run's leftover), and
//! with `--test-fire N` and a trigger box: N pulses on the box's camera line, the frames that came
//! back, how late their timestamps are after the box's pulse, and the misses. The camera is
//! left as found (the driver writes its configuration back when the test ends).

use crate::devices::CameraSpec;
use crate::{errln, outln};
use hitl_drivers::light::{TriggerBox, TriggerBoxConfig};
use hitl_drivers::orbbec::{
    pick_camera, probe, CameraInfo, OrbbecCamera, OrbbecOptions, TriggerChoice,
};
use hitl_hal::{
    CaptureRequest, Clock as _, Intrinsics, Lifecycle as _, MonotonicClock, RgbdCamera as _,
    StreamConfig, TimestampSource, Trigger as _, TriggerLines,
};
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// Pulses of `--test-fire` with a camera go out this far apart: 10 Hz, under the 15 Hz an
/// Orbbec camera follows at its 30 fps stream (the preflight's capture-rate rule).
const PULSE_PERIOD: Duration = Duration::from_millis(100);

/// List the cameras the Orbbec SDK sees; with `--camera`, none (or not the one named) is a
/// failure. `test_fire`: the trigger box's port and the number of pulses.
pub(super) fn probe_camera(
    spec: Option<CameraSpec>,
    test_fire: Option<(&str, u32)>,
) -> Result<(), String> {
    let named = match spec {
        Some(CameraSpec::Orbbec(o)) => Some(o),
        _ => None,
    };
    let library = OrbbecOptions::default_library();
    let cameras = match probe(&library) {
        Ok(c) => c,
        Err(e) if named.is_some() => return Err(e.to_string()),
        Err(e) => {
            outln!("cameras: cannot list ({e})");
            return Ok(());
        }
    };
    if cameras.is_empty() {
        outln!("cameras: none found (Orbbec SDK at {})", library.display());
        return match named {
            Some(_) => Err("no Orbbec camera connected (the Orbbec SDK sees none)".into()),
            None => Ok(()),
        };
    }
    outln!("cameras:");
    for c in &cameras {
        for line in c.report().lines() {
            outln!("  {line}");
        }
    }
    let Some(o) = named else { return Ok(()) };
    let serials: Vec<String> = cameras.iter().map(|c| c.serial.clone()).collect();
    let wanted = o.serial.map(|s| s.to_string());
    let index = pick_camera(&serials, wanted.as_deref()).map_err(|e| e.message().to_string());
    let Some((port, n)) = test_fire else {
        // Listing several cameras is fine; a serial that is not connected is not.
        return match (index, wanted) {
            (Err(e), Some(_)) => Err(e),
            _ => Ok(()),
        };
    };
    let info = &cameras[index? as usize];
    test_fire_camera(info, port, n)
}

/// The colour size to stream for the test: 1280x800 where offered in RGB, else the largest RGB.
fn test_size(info: &CameraInfo) -> Result<(u32, u32), String> {
    const RGB: i32 = 22;
    let rgb: Vec<_> = info.color_profiles.iter().filter(|p| p.format == RGB).collect();
    if rgb.iter().any(|p| (p.width, p.height) == (1280, 800)) {
        return Ok((1280, 800));
    }
    rgb.iter()
        .max_by_key(|p| u64::from(p.width) * u64::from(p.height))
        .map(|p| (p.width, p.height))
        .ok_or_else(|| format!("Orbbec camera {} offers no RGB colour stream", info.serial))
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((p / 100.0) * (sorted.len() as f64 - 1.0)).round() as usize;
    sorted.get(i).copied().unwrap_or(f64::NAN)
}

/// Fire `n` pulses through the box on `port` at the camera `info`, hardware-triggered, and say
/// what came back. Exit 5 (an error) when a pulse got no frame.
fn test_fire_camera(info: &CameraInfo, port: &str, n: u32) -> Result<(), String> {
    let (width, height) = test_size(info)?;
    let clock = MonotonicClock::new();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the I/O runtime: {e}"))?;
    let mut tb = rt
        .block_on(TriggerBox::open(port, TriggerBoxConfig::default(), clock.clone()))
        .map_err(|e| format!("trigger box on {port}: {e}"))?;
    let options = OrbbecOptions {
        clock: clock.clone(),
        trigger: TriggerChoice::Hardware,
        serial: Some(info.serial.clone()),
        ..Default::default()
    };
    let mut cam = OrbbecCamera::open(options).map_err(|e| e.to_string())?;
    if let Some(w) = cam.found().warning() {
        errln!("warning: Orbbec camera {}: {w}", info.serial);
    }
    let k = Intrinsics {
        width,
        height,
        fx: 1.0,
        fy: 1.0,
        cx: f64::from(width) / 2.0,
        cy: f64::from(height) / 2.0,
        distortion: Default::default(),
    };
    let tested = (|| {
        cam.configure(&StreamConfig { intrinsics: k, mask: false }).map_err(|e| e.to_string())?;
        cam.arm_trigger().map_err(|e| e.to_string())?;
        fire_and_count(&mut cam, &mut tb, port, n, clock)
    })();
    let closed = cam.stop();
    let _ = tb.stop();
    match &closed {
        Ok(()) => outln!(
            "  camera {}: configuration written back ({})",
            info.serial,
            cam.found().leftover.as_ref().map_or(cam.found().sync, |l| l.saved.sync)
        ),
        Err(e) => errln!("  camera {}: configuration NOT written back: {e}", info.serial),
    }
    drop(cam);
    drop(rt);
    tested?;
    closed.map_err(|e| e.to_string())
}

fn fire_and_count(
    cam: &mut OrbbecCamera,
    tb: &mut TriggerBox,
    port: &str,
    n: u32,
    clock: MonotonicClock,
) -> Result<(), String> {
    let armed = cam.armed().copied();
    outln!(
        "  test fire: {n} pulse(s) {} ms apart on trigger:{port}'s camera line, camera {}",
        PULSE_PERIOD.as_millis(),
        armed.map_or("?".to_string(), |a| format!("{} at {} + {}", a.mode, a.color, a.depth))
    );
    const CAMERA: TriggerLines = TriggerLines { camera: true, light: false };
    let mut fired_at: HashMap<u64, Option<u64>> = HashMap::new();
    let mut frames: Vec<(u64, u64, TimestampSource)> = Vec::new();
    let mut poll = |cam: &mut OrbbecCamera, tb: &mut TriggerBox, frames: &mut Vec<_>| {
        while let Ok(Some(f)) = cam.poll_frame() {
            frames.push((f.request.tick, f.exposure_ns, f.timestamp));
        }
        while let Ok(Some(r)) = tb.poll_fired() {
            fired_at.insert(r.tick, tb.device_to_host_ns(r.device_us));
        }
    };
    for i in 0..u64::from(n) {
        let start = Instant::now();
        let now = clock.now_ns();
        // The request first: the pulse's frame can reach the driver before this thread runs
        // again, and a frame no request waits for is dropped as stale.
        cam.trigger(CaptureRequest { tick: i, fired_ns: now }).map_err(|e| e.to_string())?;
        tb.fire(i, CAMERA).map_err(|e| format!("trigger box on {port}: fire {i}: {e}"))?;
        while start.elapsed() < PULSE_PERIOD {
            poll(cam, tb, &mut frames);
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    // The last frames and answers: up to the driver's frame timeout.
    let end = Instant::now() + Duration::from_millis(1200);
    while Instant::now() < end && frames.len() < n as usize {
        poll(cam, tb, &mut frames);
        std::thread::sleep(Duration::from_millis(2));
    }
    poll(cam, tb, &mut frames);
    let mut late_ms: Vec<f64> = frames
        .iter()
        .filter_map(|(tick, exposure, _)| {
            let fired = (*fired_at.get(tick)?)?;
            Some((*exposure as f64 - fired as f64) / 1e6)
        })
        .collect();
    late_ms.sort_by(f64::total_cmp);
    let received = frames.len();
    let missed = (n as usize).saturating_sub(received);
    let stamp = match frames.first().map(|f| f.2) {
        Some(TimestampSource::DeviceExposure) => "exposure (the SDK's global timestamp)",
        Some(TimestampSource::HostArrival) => "arrival on the host (no global timestamp)",
        None => "none",
    };
    outln!(
        "  test fire: {received} of {n} frames received, {missed} missed (driver: missed {}, \
         stale {}, refused {})",
        cam.frames_missed(),
        cam.frames_stale(),
        cam.frames_refused()
    );
    if late_ms.is_empty() {
        outln!("  trigger to frame timestamp: no frame with a box fire time to compare");
    } else {
        outln!(
            "  trigger to frame timestamp ({stamp}): p50 {:.3} ms, p99 {:.3} ms, min {:.3} ms, \
             max {:.3} ms over {} frames (box clock known to +-{:.0} us)",
            percentile(&late_ms, 50.0),
            percentile(&late_ms, 99.0),
            late_ms[0],
            late_ms[late_ms.len() - 1],
            late_ms.len(),
            tb.clock_uncertainty_ns().unwrap_or(0) as f64 / 1e3
        );
    }
    if let Some(e) = cam.fault_detail() {
        return Err(e.to_string());
    }
    if missed > 0 {
        return Err(format!(
            "{missed} of {n} pulses got no frame: is the trigger box's camera line wired to the \
             camera's sync input (docs/devices.md)?"
        ));
    }
    Ok(())
}
