//! The link to the arm: the command client's address, the report reader (on the real-time
//! scheduler just below the loop), the first report, and the embedded MuJoCo stub when the run
//! targets it.

#[cfg(feature = "stub")]
use super::devices::TargetScene;
use super::RunError;
use crate::rt::{self, slot::LatestSlot};
use hitl_drivers::xarm::{ReportConfig, ReportReader};
use hitl_hal::{ArmReports, ArmState, MonotonicClock};
#[cfg(feature = "stub")]
use hitl_trajectories::lab::LabConfig;
use std::net::{IpAddr, SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub(super) fn resolve(host: &str, port: u16) -> Result<SocketAddr, RunError> {
    (host, port)
        .to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| RunError::BadInput(format!("cannot resolve arm address '{host}'")))
}

/// The report reader thread: reports into the latest-value slot until told to stop or the
/// stream fails (then the tick's watchdog trips).
///
/// The reports are the loop's only view of the arm, so when the loop runs on SCHED_FIFO the
/// reader runs just below it (`fifo_priority - 1`): perception, rendering or recording on the
/// normal scheduler cannot make the watchdog see a silence the arm did not cause. Refused, it
/// stays on the normal scheduler (the loop's own report already says real-time was refused).
pub(super) fn spawn_report_reader(
    mut reader: ReportReader,
    slot: LatestSlot<ArmState>,
    stop: Arc<AtomicBool>,
    fifo_priority: Option<i32>,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new().name("hitl-reports".into()).spawn(move || {
        if let Some(p) = fifo_priority {
            let _ = rt::os::set_fifo_priority((p - 1).max(1));
        }
        while !stop.load(Ordering::Acquire) {
            match reader.next_report() {
                Ok(state) => slot.publish(state),
                Err(_) => break,
            }
        }
    })
}

/// Wait for the first arm report (the arm is alive and we know where it is).
pub(super) fn first_report(
    reader: &mut rt::slot::SlotReader<ArmState>,
    timeout: Duration,
) -> Option<ArmState> {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if let (Some(state), true) = reader.latest() {
            return Some(state);
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    None
}

/// The embedded stub, when the run targets it: the arm server, and the pieces of the scene the
/// simulated camera and light share with it.
#[cfg(feature = "stub")]
pub(super) struct EmbeddedStub {
    pub(super) handle: hitl_sim_stub::StubHandle,
    pub(super) lab_model: hitl_sim_stub::mujoco_plant::LabModel,
    pub(super) arm: hitl_sim_stub::mujoco_plant::SharedArmState,
    pub(super) light: hitl_sim_stub::camera::LightLevel,
}

#[cfg(feature = "stub")]
pub(super) fn start_stub(
    faults: &[String],
    lab: &LabConfig,
    target: &TargetScene,
) -> Result<EmbeddedStub, RunError> {
    use hitl_sim_stub::mjcf::TargetModel as StubTarget;
    use hitl_sim_stub::mujoco_plant::{LabModel, MujocoPlant};
    use hitl_sim_stub::{Fault, Stub, StubConfig};
    let faults = faults
        .iter()
        .map(|s| s.parse::<Fault>().map_err(|e| RunError::BadInput(e.to_string())))
        .collect::<Result<Vec<_>, _>>()?;
    let stub_target = StubTarget {
        mesh: Some(target.model.vertices_faces()),
        greatest_dimension_m: target.model.greatest_dimension_m() * target.scale,
    };
    let lab_model = LabModel::generated(lab, &stub_target)
        .map_err(|e| RunError::Device(format!("stub scene: {e}")))?;
    let plant = MujocoPlant::from_lab_model(lab_model.clone());
    let arm = plant.shared_state();
    let config = StubConfig { faults, ..StubConfig::ephemeral() };
    let handle =
        Stub::start(config, Box::new(plant)).map_err(|e| RunError::Device(format!("stub: {e}")))?;
    Ok(EmbeddedStub { handle, lab_model, arm, light: Default::default() })
}

pub(super) fn connect_reports(
    host: IpAddr,
    port: u16,
    codes_port: Option<u16>,
    clock: MonotonicClock,
) -> Result<ReportReader, RunError> {
    let config = ReportConfig { port: Some(port), codes_port, clock, ..ReportConfig::default() };
    ReportReader::connect(host, config)
        .map_err(|e| RunError::Device(format!("arm report stream at {host}:{port}: {e}")))
}
