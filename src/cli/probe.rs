//! `hitl probe`: commission the enclosure's devices without moving anything.
//!
//! Lists the serial ports and cameras it can see, then opens each device the operator names and
//! prints what it answers: the trigger box's inputs, the DMX widget, the arm's identity, state,
//! codes and joint-limit table, the camera's profiles and sync modes. Nothing is enabled and no
//! command that could move the arm is sent (only reads: serial number, version, state, codes).
//! Exit 0 when every named device answered, 5 naming the first one that did not, 2 for bad flags.

use crate::cli::device_flags::DeviceFlags;
use crate::devices::{CameraSpec, LightSpec, TriggerSpec};
use crate::exit;
use crate::{errln, outln};
use hitl_drivers::light::enttec::{probe_widget, Reply};
use hitl_drivers::light::{TriggerBox, TriggerBoxConfig};
use hitl_drivers::xarm::{ClientConfig, XarmClient};
use hitl_hal::{Arm as _, Inputs as _, MonotonicClock};
use hitl_trajectories::joint_table::JointTable;
use std::time::Duration;

/// Commission devices: list what is connected and check that each named device answers. The
/// device flags are `run`'s and `calibrate`'s; only the devices named are opened.
#[derive(Debug, clap::Args)]
pub struct ProbeArgs {
    #[command(flatten)]
    pub devices: DeviceFlags,
}

/// One named device that did not answer.
struct Failed {
    device: &'static str,
    why: String,
}

pub fn run(args: ProbeArgs) -> u8 {
    list_serial_ports();
    let mut failed: Vec<Failed> = Vec::new();
    let d = &args.devices;
    if let Some(spec) = &d.light {
        if let Err(why) = probe_light(spec) {
            failed.push(Failed { device: "light", why });
        }
    }
    // A box named as both light and trigger answers once.
    let probed_as_light =
        |port: &str| matches!(&d.light, Some(LightSpec::Trigger { port: p }) if p == port);
    if let Some(port) =
        d.trigger.as_ref().and_then(TriggerSpec::port).filter(|p| !probed_as_light(p))
    {
        if let Err(why) = with_runtime(probe_trigger_box(port)) {
            failed.push(Failed { device: "trigger", why });
        }
    }
    if let Some(host) = &d.arm {
        if let Err(why) = probe_arm(host) {
            failed.push(Failed { device: "arm", why });
        }
    }
    if let Err(why) = probe_camera(matches!(d.camera, Some(CameraSpec::Orbbec(_)))) {
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

fn probe_light(spec: &LightSpec) -> Result<(), String> {
    match spec {
        LightSpec::Dmx { port, .. } => with_runtime(probe_widget_on(port, spec)),
        LightSpec::Trigger { port } => with_runtime(probe_trigger_box(port)),
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

/// The trigger box: its inputs, and how well its clock is known.
async fn probe_trigger_box(port: &str) -> Result<(), String> {
    let mut tb = TriggerBox::open(port, TriggerBoxConfig::default(), MonotonicClock::new())
        .await
        .map_err(|e| e.to_string())?;
    // `open` has already seen the ping's acknowledgement and a first input report.
    let inputs = tb.read().map_err(|e| e.to_string())?;
    outln!(
        "trigger box trigger:{port}: answered the ping; e-stop {}, door {}",
        if inputs.estop_pressed { "PRESSED" } else { "released" },
        if inputs.door_open { "OPEN" } else { "closed" }
    );
    if let Some(u) = tb.clock_uncertainty_ns() {
        outln!("  clock offset known to {:.0} us", u as f64 / 1e3);
    }
    Ok(())
}

fn probe_arm(host: &str) -> Result<(), String> {
    let config = ClientConfig::default();
    let connected = match host.parse::<std::net::SocketAddr>() {
        Ok(addr) => XarmClient::connect(addr, config),
        Err(_) => XarmClient::connect_host(host, config),
    };
    let mut arm = connected.map_err(|e| e.to_string())?;
    let serial = arm.serial_number().map_err(|e| format!("serial number: {e}"))?;
    let version = arm.version().map_err(|e| format!("firmware version: {e}"))?;
    let state = arm.state().map_err(|e| format!("state: {e}"))?;
    let (error, warning) = arm.codes().map_err(|e| format!("error codes: {e}"))?;
    let table = JointTable::for_serial(&serial);
    outln!("arm {host}: serial {serial}, firmware {version}");
    outln!("  state {state}, error code {error}, warning code {warning}");
    let limits = table
        .limits()
        .iter()
        .enumerate()
        .map(|(j, (lo, hi))| format!("J{} {:.4}..{:.4}", j + 1, lo, hi))
        .collect::<Vec<_>>()
        .join(", ");
    outln!("  joint-limit table {table}: {limits} rad");
    Ok(())
}

/// List the cameras the Orbbec SDK sees; with `--camera`, none is a failure.
fn probe_camera(named: bool) -> Result<(), String> {
    use hitl_drivers::orbbec::{probe, OrbbecOptions};
    let library = OrbbecOptions::default_library();
    let cameras = match probe(&library) {
        Ok(c) => c,
        Err(e) if named => return Err(e.to_string()),
        Err(e) => {
            outln!("cameras: cannot list ({e})");
            return Ok(());
        }
    };
    if cameras.is_empty() {
        outln!("cameras: none found (Orbbec SDK at {})", library.display());
        return if named { Err("no Orbbec camera connected".into()) } else { Ok(()) };
    }
    outln!("cameras:");
    for c in &cameras {
        for line in c.describe().lines() {
            outln!("  {line}");
        }
    }
    Ok(())
}
