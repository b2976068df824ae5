//! `hitl probe`: commission the enclosure's devices without moving anything.
//!
//! Lists the serial ports and cameras it can see, then opens each device the operator names and
//! prints what it answers: the trigger box's firmware, protocol, inputs and clock (and, with
//! `--test-fire N`, N camera pulses with their times and round trips), the DMX widget, the arm's
//! identity, state, codes and joint-limit table, the camera's profiles and sync modes. Nothing is
//! enabled and no command that could move the arm is sent (only reads: serial number, version,
//! state, codes). Exit 0 when every named device answered, 5 naming the first one that did not,
//! 2 for bad flags.

use crate::cli::device_flags::DeviceFlags;
use crate::devices::{CameraSpec, LightSpec, TriggerSpec};
use crate::exit;
use crate::{errln, outln};
use hitl_drivers::light::enttec::{probe_widget, Reply};
use hitl_drivers::light::{TriggerBox, TriggerBoxConfig};
use hitl_hal::{Clock as _, Inputs as _, MonotonicClock, Trigger as _, TriggerLines};
use std::time::Duration;

/// Commission devices: list what is connected and check that each named device answers. The
/// device flags are `run`'s and `calibrate`'s; only the devices named are opened.
#[derive(Debug, clap::Args)]
pub struct ProbeArgs {
    #[command(flatten)]
    pub devices: DeviceFlags,
    /// Fire the trigger box's camera line N times (20 ms apart) and print each pulse's time on
    /// the box's clock and on the host's, and the round trips (needs a box: --trigger or
    /// --light trigger:DEV). Exit 5 unless every pulse was acknowledged. With --camera as well,
    /// the N pulses fire the camera instead, 100 ms apart: the probe counts the frames that come
    /// back, the misses, and how late each frame's timestamp is after the box's pulse (p50/p99);
    /// exit 5 unless every pulse got its frame.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub test_fire: Option<u32>,
    /// The arm's real report port (a box's 30003); its normal report (error and warning codes)
    /// is read two ports below, as on a box. Only with --arm.
    #[arg(long, value_name = "P", default_value_t = 30003,
          value_parser = clap::value_parser!(u16).range(3..))]
    pub report_port: u16,
    /// Step the light named by --light through 0, 0.25, 0.5, 0.75, 1 and back to 0, 400 ms
    /// each, checking the driver after every step.
    #[arg(long)]
    pub test_levels: bool,
}

mod arm;
mod camera;
mod levels;

/// One named device that did not answer.
struct Failed {
    device: &'static str,
    why: String,
}

pub fn run(args: ProbeArgs) -> u8 {
    let d = &args.devices;
    let trigger_port = d.trigger.as_ref().and_then(TriggerSpec::port);
    let light_box = matches!(&d.light, Some(LightSpec::Trigger { .. }));
    if args.test_fire.is_some() && trigger_port.is_none() && !light_box {
        errln!(
            "probe: --test-fire needs a trigger box (--trigger trigger:DEV or --light trigger:DEV)"
        );
        return exit::BAD_INPUT;
    }
    if args.test_levels && d.light.is_none() {
        errln!("probe: --test-levels needs a light (--light dmx:DEV or trigger:DEV)");
        return exit::BAD_INPUT;
    }
    // With a camera named, --test-fire fires the camera (and counts its frames): the box's own
    // test then sends no pulses of its own.
    let camera_fires = matches!(d.camera, Some(CameraSpec::Orbbec(_))) && args.test_fire.is_some();
    let box_test_fire = if camera_fires { None } else { args.test_fire };
    list_serial_ports();
    let mut failed: Vec<Failed> = Vec::new();
    // A box named as both light and trigger answers once (and test-fires as the trigger).
    let probed_as_light =
        |port: &str| matches!(&d.light, Some(LightSpec::Trigger { port: p }) if p == port);
    let test_fire_light = if trigger_port.is_some() { None } else { box_test_fire };
    if let Some(spec) = &d.light {
        if let Err(why) = probe_light(spec, test_fire_light) {
            failed.push(Failed { device: "light", why });
        }
    }
    if let Some(port) = trigger_port {
        let test_fire = box_test_fire;
        let probe = if probed_as_light(port) && test_fire.is_none() {
            Ok(())
        } else {
            with_runtime(probe_trigger_box(port, test_fire, !probed_as_light(port)))
        };
        if let Err(why) = probe {
            failed.push(Failed { device: "trigger", why });
        }
    }
    if let (true, Some(spec)) = (args.test_levels, &d.light) {
        if let Err(why) = levels::test_levels(spec) {
            failed.push(Failed { device: "light", why });
        }
    }
    if let Some(host) = &d.arm {
        if let Err(why) = arm::probe_arm(host, args.report_port) {
            failed.push(Failed { device: "arm", why });
        }
    }
    let box_port = trigger_port.or(match &d.light {
        Some(LightSpec::Trigger { port }) => Some(port.as_str()),
        _ => None,
    });
    let fire = box_port.zip(args.test_fire).filter(|_| camera_fires);
    if let Err(why) = camera::probe_camera(d.camera, fire) {
        failed.push(Failed { device: "camera", why });
    }
    match failed.first() {
        None => {
            outln!("probe: every named device answered");
            exit::OK
        }
        Some(first) => {
            for f in &failed {
                errln!("probe: {} did not answer: {}", f.device, f.why);
            }
            errln!("probe: {} failed (exit 5)", first.device);
            exit::DEVICE
        }
    }
}

fn list_serial_ports() {
    match tokio_serial::available_ports() {
        Ok(ports) if ports.is_empty() => outln!("serial ports: none found"),
        Ok(ports) => {
            outln!("serial ports:");
            for p in ports {
                let what = match &p.port_type {
                    tokio_serial::SerialPortType::UsbPort(u) => format!(
                        "USB {:04x}:{:04x} {} {}",
                        u.vid,
                        u.pid,
                        u.manufacturer.as_deref().unwrap_or(""),
                        u.product.as_deref().unwrap_or("")
                    ),
                    tokio_serial::SerialPortType::PciPort => "PCI".into(),
                    tokio_serial::SerialPortType::BluetoothPort => "Bluetooth".into(),
                    tokio_serial::SerialPortType::Unknown => "unknown".into(),
                };
                outln!("  {}  {}", p.port_name, what.trim());
            }
        }
        Err(e) => errln!("serial ports: cannot list ({e})"),
    }
}

/// Run one probe's I/O on a small runtime of its own (the drivers' tasks live on it).
fn with_runtime(
    probe: impl std::future::Future<Output = Result<(), String>>,
) -> Result<(), String> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the I/O runtime: {e}"))?;
    rt.block_on(probe)
}

fn probe_light(spec: &LightSpec, test_fire: Option<u32>) -> Result<(), String> {
    match spec {
        LightSpec::Dmx { port, .. } => with_runtime(probe_widget_on(port, spec)),
        LightSpec::Trigger { port } => with_runtime(probe_trigger_box(port, test_fire, true)),
        LightSpec::Sim | LightSpec::None => {
            outln!("light {spec}: nothing to probe (not a serial device)");
            Ok(())
        }
    }
}

/// A widget answers a parameters request; a bare serial port (or a dead widget) does not.
async fn probe_widget_on(port: &str, spec: &LightSpec) -> Result<(), String> {
    let reply = probe_widget(port, Duration::from_millis(500)).await.map_err(|e| e.to_string())?;
    match reply {
        Reply::Parameters { firmware, break_time, mab_time, rate } => outln!(
            "DMX widget {spec}: Enttec DMX USB Pro firmware {}.{}, break {:.0} us, \
             mark-after-break {:.0} us, {}",
            firmware >> 8,
            firmware & 0xFF,
            f64::from(break_time) * 10.67,
            f64::from(mab_time) * 10.67,
            if rate == 0 { "as fast as possible".to_string() } else { format!("{rate} packets/s") }
        ),
        other => outln!("DMX widget {spec}: answered ({other:?})"),
    }
    Ok(())
}

/// The trigger box: its firmware, protocol and inputs (`describe`: printed, once per box), how
/// well its clock is known, and `test_fire` camera pulses.
async fn probe_trigger_box(
    port: &str,
    test_fire: Option<u32>,
    describe: bool,
) -> Result<(), String> {
    let clock = MonotonicClock::new();
    let mut tb = TriggerBox::open(port, TriggerBoxConfig::default(), clock.clone())
        .await
        .map_err(|e| e.to_string())?;
    // `open` has seen the ping's answer, the version and a first input report.
    let inputs = tb.read().map_err(|e| e.to_string())?;
    if describe {
        let version = tb.version().map_or_else(
            || "version unknown".to_string(),
            |v| format!("firmware {}, protocol {}", v.firmware, v.protocol),
        );
        outln!(
            "trigger box trigger:{port}: {version}; e-stop {}, door {}",
            if inputs.estop_pressed { "PRESSED" } else { "released" },
            if inputs.door_open { "OPEN" } else { "closed" }
        );
        if let (Some(m), Some(u)) = (tb.clock_mapping(), tb.clock_uncertainty_ns()) {
            outln!(
                "  clock: mapped onto the host's over {} round trip(s), to +-{:.0} us",
                m.samples,
                u as f64 / 1e3
            );
        }
    }
    let Some(n) = test_fire else { return Ok(()) };
    test_fires(&mut tb, port, n, clock).await
}

/// Fire the camera line `n` times, 20 ms apart (the pulse is 1 ms), each after the previous one's
/// answer; print each pulse's time on both clocks and the round trip, then their spread.
async fn test_fires(
    tb: &mut TriggerBox,
    port: &str,
    n: u32,
    clock: MonotonicClock,
) -> Result<(), String> {
    const CAMERA: TriggerLines = TriggerLines { camera: true, light: false };
    outln!("  test fire: {n} camera pulse(s), 20 ms apart");
    let mut round_trips_ms = Vec::with_capacity(n as usize);
    for i in 1..=u64::from(n) {
        let asked = clock.now_ns();
        tb.fire(i, CAMERA).map_err(|e| format!("test fire {i}: {e}"))?;
        let deadline = asked + 200_000_000;
        let report = loop {
            match tb.poll_fired() {
                Ok(Some(r)) => break Some(r),
                Ok(None) if clock.now_ns() < deadline => {
                    tokio::time::sleep(std::time::Duration::from_micros(200)).await;
                }
                Ok(None) => break None,
                Err(e) => {
                    errln!("  fire {i}: {e}");
                    break None;
                }
            }
        };
        let Some(r) = report else { break };
        let rtt_ms = r.acked_ns.saturating_sub(asked) as f64 / 1e6;
        round_trips_ms.push(rtt_ms);
        let host = match (r.host_ns, r.host_error_ns) {
            (Some(h), Some(e)) => {
                format!("host {:.6} s +- {:.0} us", h as f64 / 1e9, e as f64 / 1e3)
            }
            _ => "host time unknown (the box's clock is not mapped)".to_string(),
        };
        outln!("  fire {i}: box {} us, {host}, answered in {rtt_ms:.2} ms", r.device_us);
        tokio::time::sleep_until(
            tokio::time::Instant::now() + std::time::Duration::from_millis(20),
        )
        .await;
    }
    let busy = tb.busy();
    if busy.answers > 0 {
        outln!(
            "  busy answers {} (sent again {}, given up {})",
            busy.answers,
            busy.retried,
            busy.given_up
        );
    }
    let answered = round_trips_ms.len();
    let mut sorted = round_trips_ms.clone();
    sorted.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        let i = ((p / 100.0) * (sorted.len() as f64 - 1.0)).round() as usize;
        sorted.get(i).copied().unwrap_or(f64::NAN)
    };
    if answered > 0 {
        outln!(
            "  test fire: {answered} of {n} answered; round trip (fire to answer) p50 {:.2} ms, \
             p99 {:.2} ms, max {:.2} ms",
            pct(50.0),
            pct(99.0),
            sorted.last().copied().unwrap_or(f64::NAN)
        );
    }
    if answered == n as usize {
        Ok(())
    } else {
        Err(format!(
            "trigger box on {port}: {answered} of {n} test fires answered{}",
            tb.fault().map(|f| format!(" ({})", f.message())).unwrap_or_default()
        ))
    }
}
