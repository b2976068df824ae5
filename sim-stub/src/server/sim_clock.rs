//! The stub on a simulated clock (`StubConfig::simulated`): no thread keeps time. The host
//! advances the box with [`SimDriver::advance_to`], which steps the physics by whole steps,
//! releases the faults due by then, and writes the reports due by then to every report
//! connection, in the order of simulated time (codes streams before state streams at the same
//! instant, so a reader that merges them sees the codes of that instant). Commands are answered
//! as they come, at the simulated time they find.
//!
//! The host knows where the box stands from counters: commands answered (against what its client
//! wrote), reports written per stream kind (against what its reader has read). With those it can
//! wait until the box has heard everything sent before time moves, and the controller has heard
//! everything the box said: the lockstep that makes a simulated run repeat exactly.

use super::Shared;
use crate::faults::{Fault, FaultSchedule};
use hitl_drivers::xarm::report::{encode_report, ReportKind, MAX_REPORT_LEN};
use std::io::Write;
use std::net::TcpStream;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// One report connection, written by [`SimDriver::advance_to`].
struct ReportConn {
    stream: TcpStream,
    kind: ReportKind,
    /// Simulated time its next report is due.
    next_ns: u64,
    period_ns: u64,
    /// The drop-connection epoch it was opened in.
    epoch: u64,
}

/// What the simulated clock adds to the box's shared state.
pub struct SimState {
    /// The box's simulated time, ns (whole physics steps).
    pub now_ns: AtomicU64,
    /// Command frames answered (or, for keep-alives, taken).
    pub commands_answered: AtomicU64,
    /// Command connections open now.
    pub command_connections: AtomicU64,
    /// Reports written per kind, in [`ReportKind::ALL`]'s order.
    reports_written: [AtomicU64; 4],
    /// Report connections waiting for their first report (the accept threads hand them here).
    new_reports: Mutex<Vec<ReportConn>>,
}

impl SimState {
    pub fn new() -> Self {
        Self {
            now_ns: AtomicU64::new(0),
            commands_answered: AtomicU64::new(0),
            command_connections: AtomicU64::new(0),
            reports_written: Default::default(),
            new_reports: Mutex::new(Vec::new()),
        }
    }

    /// Hand a freshly accepted report connection to the driver: its first report goes out at
    /// the next advance.
    pub fn add_report_connection(&self, stream: TcpStream, kind: ReportKind, epoch: u64) {
        let period_ns = (1e9 / kind.rate_hz()).round() as u64;
        let now = self.now_ns.load(Ordering::Acquire);
        let conn = ReportConn { stream, kind, next_ns: now, period_ns, epoch };
        self.new_reports.lock().unwrap_or_else(|e| e.into_inner()).push(conn);
    }

    /// Reports of `kind` written so far.
    pub fn reports_written(&self, kind: ReportKind) -> u64 {
        self.reports_written[kind_index(kind)].load(Ordering::Acquire)
    }

    /// Report connections accepted so far and not yet closed or written to.
    pub fn pending_report_connections(&self) -> usize {
        self.new_reports.lock().unwrap_or_else(|e| e.into_inner()).len()
    }
}

impl Default for SimState {
    fn default() -> Self {
        Self::new()
    }
}

fn kind_index(kind: ReportKind) -> usize {
    ReportKind::ALL.iter().position(|k| *k == kind).unwrap_or(0)
}

/// The host's side of a simulated stub: advances it.
pub struct SimDriver {
    faults: FaultSchedule,
    reports: Vec<ReportConn>,
    buf: Box<[u8; MAX_REPORT_LEN]>,
}

impl SimDriver {
    pub fn new(faults: Vec<Fault>) -> Self {
        Self {
            faults: FaultSchedule::new(faults),
            reports: Vec::new(),
            buf: Box::new([0; MAX_REPORT_LEN]),
        }
    }

    /// Step the box to `t_ns` (whole physics steps, never back): at each instant the faults
    /// due fire, then the reports due go out, then the physics steps.
    pub fn advance_to(&mut self, shared: &Shared, sim: &SimState, t_ns: u64) {
        let step_ns = ((shared.physics_dt * 1e9).round() as u64).max(1);
        self.take_new_connections(sim);
        loop {
            let now = sim.now_ns.load(Ordering::Acquire);
            while let Some(f) = self.faults.next_due(now as f64 * 1e-9) {
                shared.apply(f.kind);
            }
            self.write_reports_due(shared, sim, now);
            if now + step_ns > t_ns {
                break;
            }
            shared.lock_arm().step(shared.physics_dt);
            shared.counters.steps.fetch_add(1, Ordering::Relaxed);
            sim.now_ns.store(now + step_ns, Ordering::Release);
        }
    }

    fn take_new_connections(&mut self, sim: &SimState) {
        let mut new = sim.new_reports.lock().unwrap_or_else(|e| e.into_inner());
        self.reports.append(&mut new);
        // Codes streams first: at one instant a reader merging them sees that instant's codes.
        self.reports.sort_by_key(|c| !c.kind.has_codes());
    }

    fn write_reports_due(&mut self, shared: &Shared, sim: &SimState, now: u64) {
        let epoch = shared.drop_epoch.load(Ordering::SeqCst);
        let stalled = shared.stall_until_ns.load(Ordering::SeqCst) > now;
        let buf = &mut self.buf[..];
        self.reports.retain_mut(|c| {
            if shared.stopping() || c.epoch != epoch {
                let _ = c.stream.shutdown(std::net::Shutdown::Both);
                return false;
            }
            while c.next_ns <= now {
                c.next_ns += c.period_ns;
                if stalled {
                    continue;
                }
                let n = {
                    let mut arm = shared.lock_arm();
                    let data = arm.report(now / 1000);
                    let id = arm.identity();
                    encode_report(buf, c.kind, &data, &id)
                };
                let Ok(n) = n else { return false };
                if c.stream.write_all(&buf[..n]).is_err() {
                    return false;
                }
                shared.counters.reports_sent.fetch_add(1, Ordering::Relaxed);
                sim.reports_written[kind_index(c.kind)].fetch_add(1, Ordering::AcqRel);
            }
            true
        });
    }
}
