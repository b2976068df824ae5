//! OS settings for the real-time thread (Linux): SCHED_FIFO, mlockall, CPU affinity, minimal
//! timer slack and a zero CPU wake-up latency request (`/dev/cpu_dma_latency`, held for the rest
//! of the process, as cyclictest does: it keeps idle cores out of deep sleep states, whose exit
//! latency otherwise adds to every wake-up), plus the absolute-deadline sleep. This is the FFI module of `rt`: every `unsafe`
//! block is a plain libc call on values we own, with a `SAFETY:` note.
//!
//! Each setting is optional and falls back when the OS refuses (no privilege, a container): the
//! [`RtReport`] says what took effect so the operator is told, never silently degraded.
#![allow(unsafe_code)]

use std::time::Duration;

/// What the real-time thread asks of the OS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtOptions {
    /// SCHED_FIFO priority (1-99); `None` leaves the normal scheduler.
    pub fifo_priority: Option<i32>,
    /// Lock all current and future pages in memory (no page faults in the tick).
    pub lock_memory: bool,
    /// Pin the thread to this CPU.
    pub cpu: Option<usize>,
    /// Sleep until this long before the deadline, then spin (0 = sleep all the way).
    pub spin: Duration,
}

impl Default for RtOptions {
    fn default() -> Self {
        Self { fifo_priority: Some(80), lock_memory: true, cpu: None, spin: Duration::ZERO }
    }
}

impl RtOptions {
    /// The defaults at the `--rt-priority` the operator gave: 0 leaves the normal scheduler.
    pub fn with_priority(priority: i32) -> Self {
        Self { fifo_priority: (priority > 0).then_some(priority), ..Self::default() }
    }
}

/// What took effect, for the operator and the run record.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct RtReport {
    pub fifo: Option<i32>,
    pub memory_locked: bool,
    pub cpu: Option<usize>,
    pub timer_slack_ns: Option<u64>,
    /// The CPU wake-up latency requested through `/dev/cpu_dma_latency`, microseconds.
    pub cpu_dma_latency_us: Option<u32>,
    /// One line per setting the OS refused, saying which and why.
    pub fallbacks: Vec<String>,
}

impl RtReport {
    /// A one-line summary such as "SCHED_FIFO 80, memory locked, timer slack 1 ns".
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        match self.fifo {
            Some(p) => parts.push(format!("SCHED_FIFO {p}")),
            None => parts.push("normal scheduler".to_string()),
        }
        parts.push(if self.memory_locked { "memory locked" } else { "memory not locked" }.into());
        if let Some(c) = self.cpu {
            parts.push(format!("pinned to CPU {c}"));
        }
        if let Some(s) = self.timer_slack_ns {
            parts.push(format!("timer slack {s} ns"));
        }
        if let Some(l) = self.cpu_dma_latency_us {
            parts.push(format!("CPU wake-up latency {l} us"));
        }
        parts.join(", ")
    }
}

fn last_os_error() -> String {
    std::io::Error::last_os_error().to_string()
}

/// Apply `options` to the calling thread. Never fails: refusals land in `fallbacks`.
pub fn apply(options: &RtOptions) -> RtReport {
    let mut report = RtReport::default();

    // SAFETY: prctl(PR_SET_TIMERSLACK, 1) takes plain integers and affects only this thread.
    if unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) } == 0 {
        report.timer_slack_ns = Some(1);
    } else {
        report.fallbacks.push(format!("timer slack unchanged: {}", last_os_error()));
    }

    if options.lock_memory {
        // SAFETY: mlockall takes flags only; failure leaves memory as it was.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
            report.memory_locked = true;
        } else {
            report.fallbacks.push(format!("mlockall refused: {}", last_os_error()));
        }
    }

    if let Some(cpu) = options.cpu {
        // SAFETY: cpu_set_t is plain data, zeroed then filled with CPU_SET on a bounds-checked
        // index; sched_setaffinity(0, ..) applies to the calling thread only.
        let ok = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if cpu < libc::CPU_SETSIZE as usize {
                libc::CPU_SET(cpu, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
            } else {
                false
            }
        };
        if ok {
            report.cpu = Some(cpu);
        } else {
            report.fallbacks.push(format!("CPU {cpu} affinity refused: {}", last_os_error()));
        }
    }

    if let Some(priority) = options.fifo_priority {
        match set_fifo_priority(priority) {
            Ok(p) => report.fifo = Some(p),
            Err(why) => report.fallbacks.push(why),
        }
        // Only a real-time run asks the whole machine to stay awake.
        match request_cpu_dma_latency() {
            Ok(us) => report.cpu_dma_latency_us = Some(us),
            Err(why) => report.fallbacks.push(why),
        }
    }
    report
}

/// The open PM QoS request: the kernel honours it while the file stays open.
static CPU_DMA_LATENCY: std::sync::OnceLock<std::fs::File> = std::sync::OnceLock::new();

/// Ask the kernel to keep every CPU's wake-up (C-state exit) latency at 0 us for the rest of the
/// process (PM QoS through `/dev/cpu_dma_latency`; cyclictest does the same). Idempotent.
fn request_cpu_dma_latency() -> Result<u32, String> {
    use std::io::Write as _;
    if CPU_DMA_LATENCY.get().is_some() {
        return Ok(0);
    }
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")
        .map_err(|e| format!("CPU wake-up latency unchanged (/dev/cpu_dma_latency: {e})"))?;
    f.write_all(&0i32.to_ne_bytes())
        .map_err(|e| format!("CPU wake-up latency unchanged (/dev/cpu_dma_latency: {e})"))?;
    let _ = CPU_DMA_LATENCY.set(f);
    Ok(0)
}

/// Put the calling thread on SCHED_FIFO at `priority` (clamped to 1-99). Returns the priority
/// set, or why the OS refused (then the thread stays on the normal scheduler).
pub fn set_fifo_priority(priority: i32) -> Result<i32, String> {
    let param = libc::sched_param { sched_priority: priority.clamp(1, 99) };
    // SAFETY: pthread_self() is the calling thread; param is a valid, initialised struct.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(param.sched_priority)
    } else {
        Err(format!(
            "SCHED_FIFO {} refused ({}); running on the normal scheduler",
            param.sched_priority,
            std::io::Error::from_raw_os_error(rc)
        ))
    }
}

/// The monotonic clock, nanoseconds.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: ts is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    (ts.tv_sec as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec as u64)
}

/// Sleep until the monotonic clock reads `deadline_ns` (absolute: no drift from wake-up delays).
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: ts is a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_operators_priority_zero_means_the_normal_scheduler() {
        assert_eq!(RtOptions::with_priority(0).fifo_priority, None);
        let o = RtOptions::with_priority(42);
        assert_eq!(o.fifo_priority, Some(42));
        assert!(o.lock_memory && o.cpu.is_none() && o.spin.is_zero());
    }
}
