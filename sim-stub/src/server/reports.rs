//! The report ports: each connection gets frames of its port's kind at the real box's rate,
//! paced against absolute deadlines, until shutdown, a drop-connection fault or a write error.
//! A stall-reports fault pauses sending without closing.

use super::{Shared, POLL};
use hitl_drivers::xarm::report::{encode_report, ReportKind, MAX_REPORT_LEN};
use std::io::{self, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Accept loop of one report port.
pub fn serve(shared: Arc<Shared>, listener: TcpListener, kind: ReportKind) {
    let mut workers = Vec::new();
    while !shared.stopping() {
        match listener.accept() {
            Ok((stream, _)) => {
                shared.counters.connections.fetch_add(1, Ordering::Relaxed);
                let s = shared.clone();
                if let Ok(t) = shared
                    .thread_start
                    .spawn("hitl-stub-report-conn", move || connection(s, stream, kind))
                {
                    workers.push(t);
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => std::thread::sleep(POLL / 4),
            Err(_) => std::thread::sleep(POLL),
        }
        workers.retain(|t| !t.is_finished());
    }
    for t in workers {
        let _ = t.join();
    }
}

fn connection(shared: Arc<Shared>, mut stream: TcpStream, kind: ReportKind) {
    let epoch = shared.drop_epoch.load(Ordering::SeqCst);
    let _ = stream.set_nodelay(true);
    let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
    if let Some(sim) = &shared.sim {
        // On a simulated clock the host's advances write the reports (server::sim_clock).
        sim.add_report_connection(stream, kind, epoch);
        return;
    }
    let period = Duration::from_secs_f64(1.0 / kind.rate_hz());
    let mut buf = [0u8; MAX_REPORT_LEN];
    let mut next = Instant::now();
    loop {
        if shared.stopping() || shared.drop_epoch.load(Ordering::SeqCst) != epoch {
            break;
        }
        let now = Instant::now();
        if now < next {
            std::thread::sleep((next - now).min(POLL));
            continue;
        }
        next += period;
        if now > next + period {
            next = now + period;
        }
        if shared.stall_until_ns.load(Ordering::SeqCst) > shared.elapsed_ns() {
            continue;
        }
        let ts_us = shared.elapsed_ns() / 1000;
        let n = {
            let mut arm = shared.lock_arm();
            let data = arm.report(ts_us);
            let id = arm.identity();
            encode_report(&mut buf, kind, &data, &id)
        };
        let Ok(n) = n else { break };
        if stream.write_all(&buf[..n]).is_err() {
            break;
        }
        shared.counters.reports_sent.fetch_add(1, Ordering::Relaxed);
    }
    let _ = stream.shutdown(std::net::Shutdown::Both);
}
