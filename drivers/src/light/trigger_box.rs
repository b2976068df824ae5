//! The microcontroller trigger box on a serial line: camera trigger and light strobe lines,
//! a dimmable light output, and the enclosure's safety inputs (e-stop, door).
//!
//! Protocol: docs/trigger-box-protocol.md, codec in [`super::protocol`]. The tick-side handle
//! ([`TriggerBox`], cheap to clone) only touches atomics and lock-free queues; a tokio task owns
//! the port, writes queued commands, matches acknowledgements to fires, keeps the latest input
//! report, and enforces the deadlines (acknowledgement, input staleness, write). Any fault
//! (garbage, over-long line, unexpected ack, `E` line, timeout, hang-up) is sticky and returned by
//! the next call from the tick.
//!
//! The task runs on the run's tokio runtime for as long as any clone is in use (the runtime must
//! outlive the handles); [`Lifecycle::stop`] has it write what is queued, close the port and end.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crossbeam_queue::ArrayQueue;
use hitl_hal::{
    Clock, ErrorKind, ErrorType, FireReport, InputState, Inputs, Lifecycle, Light, MonotonicClock,
    Trigger, TriggerLines,
};
use tokio::io::AsyncReadExt;
use tokio::task::JoinHandle;

use super::fault::{Fault, Health, SerialError, TaskAlive, TaskEnd};
use super::protocol::{
    format_command, level_permille, parse_line, BoxLine, Command, LineBuffer, Pushed,
};
use super::serial::{check_level, classify_io, open_port, write_within};

/// Settings of a trigger box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriggerBoxConfig {
    pub baud: u32,
    /// A command not acknowledged within this is a fault.
    pub ack_timeout: Duration,
    /// Input reports older than this are a fault (the box sends them at least every 50 ms).
    pub inputs_stale_after: Duration,
    /// How often the task looks at the command queue and the deadlines.
    pub poll: Duration,
    pub write_timeout: Duration,
    /// `open` waits this long for the ping's ack and the first input report.
    pub open_timeout: Duration,
    /// Commands that may wait for the port (and acks that may be outstanding).
    pub queue: usize,
}

impl Default for TriggerBoxConfig {
    fn default() -> Self {
        Self {
            baud: 115_200,
            ack_timeout: Duration::from_millis(50),
            inputs_stale_after: Duration::from_millis(200),
            poll: Duration::from_millis(1),
            write_timeout: Duration::from_millis(50),
            open_timeout: Duration::from_secs(1),
            queue: 32,
        }
    }
}

const INPUT_VALID: u8 = 1;
const INPUT_ESTOP: u8 = 2;
const INPUT_DOOR: u8 = 4;
const LEVEL_UNSET: u32 = u32::MAX;

struct Shared {
    health: Health,
    clock: MonotonicClock,
    stale_ns: u64,
    commands: ArrayQueue<Command>,
    fired: ArrayQueue<FireReport>,
    /// Fire reports dropped because the tick did not poll them in time.
    fired_dropped: AtomicU64,
    inputs: AtomicU8,
    inputs_at_ns: AtomicU64,
    /// Latest steady level asked for, permille, or `LEVEL_UNSET`.
    level: AtomicU32,
    ping_acked: AtomicBool,
    /// Host ns minus device ns, from the acknowledgement with the shortest round trip lately.
    offset_ns: AtomicI64,
    /// That round trip, ns (`u64::MAX`: no estimate yet).
    offset_rtt_ns: AtomicU64,
    /// Asked to write what is queued and end.
    stopping: AtomicBool,
    /// The task has ended (set by its drop guard, also when it is aborted).
    task_ended: AtomicBool,
    /// Wakes `open` when the ping is acknowledged, an input report arrives or a fault trips.
    open_progress: tokio::sync::Notify,
}

impl Shared {
    fn inputs_fresh(&self, now_ns: u64) -> bool {
        let bits = self.inputs.load(Ordering::Acquire);
        bits & INPUT_VALID != 0
            && now_ns.saturating_sub(self.inputs_at_ns.load(Ordering::Acquire)) <= self.stale_ns
    }
}

struct TaskGuard {
    task: JoinHandle<()>,
    ended: std::sync::Mutex<TaskEnd>,
}

impl Drop for TaskGuard {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Owned by the task: marks it ended however it ends.
struct EndMark {
    shared: Arc<Shared>,
    _alive: TaskAlive,
}

impl Drop for EndMark {
    fn drop(&mut self) {
        self.shared.task_ended.store(true, Ordering::Release);
        self.shared.open_progress.notify_one();
    }
}

/// Handle to a trigger box: [`Trigger`], [`Inputs`] and [`Light`] (steady level through `L`,
/// flashes through `S`). Clones share one port; the task stops when the last clone is dropped.
#[derive(Clone)]
pub struct TriggerBox {
    shared: Arc<Shared>,
    _task: Arc<TaskGuard>,
    stop_timeout: Duration,
}

impl TriggerBox {
    /// Open the box at `path`, check it answers a ping and reports its inputs within
    /// `open_timeout`. Stamps use `clock` (the controller's). Must run inside a tokio runtime.
    pub async fn open(
        path: &str,
        config: TriggerBoxConfig,
        clock: MonotonicClock,
    ) -> Result<Self, SerialError> {
        if config.queue == 0 || config.poll.is_zero() || config.ack_timeout.is_zero() {
            return Err(SerialError::new(
                ErrorKind::InvalidRequest,
                "trigger box: queue, poll period and ack timeout must be positive",
            ));
        }
        let port = open_port(path, config.baud, "trigger box")?;
        let shared = Arc::new(Shared {
            health: Health::new(),
            clock,
            stale_ns: u64::try_from(config.inputs_stale_after.as_nanos()).unwrap_or(u64::MAX),
            commands: ArrayQueue::new(config.queue),
            fired: ArrayQueue::new(config.queue.max(64)),
            fired_dropped: AtomicU64::new(0),
            inputs: AtomicU8::new(0),
            inputs_at_ns: AtomicU64::new(0),
            level: AtomicU32::new(LEVEL_UNSET),
            ping_acked: AtomicBool::new(false),
            offset_ns: AtomicI64::new(0),
            offset_rtt_ns: AtomicU64::new(u64::MAX),
            stopping: AtomicBool::new(false),
            task_ended: AtomicBool::new(false),
            open_progress: tokio::sync::Notify::new(),
        });
        let _ = shared.commands.push(Command::Ping);
        let (alive, ended) = TaskEnd::new();
        let mark = EndMark { shared: Arc::clone(&shared), _alive: alive };
        let task = tokio::spawn(box_task(port, config, Arc::clone(&shared), mark));
        let tb = Self {
            shared,
            _task: Arc::new(TaskGuard { task, ended: std::sync::Mutex::new(ended) }),
            stop_timeout: config.write_timeout * 4 + config.ack_timeout + config.poll * 2,
        };
        let deadline = tokio::time::Instant::now() + config.open_timeout;
        loop {
            if tb.shared.task_ended.load(Ordering::Acquire) {
                tb.shared.health.trip(Fault::TaskEnded);
            }
            if let Some(f) = tb.shared.health.fault() {
                return Err(SerialError::new(
                    f.kind(),
                    format!("trigger box on {path}: {} while opening", f.message()),
                ));
            }
            let now = tb.shared.clock.now_ns();
            if tb.shared.ping_acked.load(Ordering::Acquire) && tb.shared.inputs_fresh(now) {
                return Ok(tb);
            }
            if tokio::time::Instant::now() >= deadline {
                return Err(SerialError::new(
                    ErrorKind::Timeout,
                    format!(
                        "trigger box on {path}: no ping acknowledgement and input report within {} ms",
                        config.open_timeout.as_millis()
                    ),
                ));
            }
            // A stored permit covers progress made since the checks above.
            let _ = tokio::time::timeout_at(deadline, tb.shared.open_progress.notified()).await;
        }
    }

    /// The fault the driver tripped on, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.shared.health.fault()
    }

    /// The box's time `device_us` on the controller's clock (ns), from the acknowledgement
    /// round trips (midpoint of the shortest recent one); `None` before the first ack.
    pub fn device_to_host_ns(&self, device_us: u64) -> Option<u64> {
        if self.shared.offset_rtt_ns.load(Ordering::Acquire) == u64::MAX {
            return None;
        }
        let off = self.shared.offset_ns.load(Ordering::Acquire);
        let host = i128::from(device_us) * 1000 + i128::from(off);
        Some(u64::try_from(host.max(0)).unwrap_or(u64::MAX))
    }

    /// Half the round trip of the acknowledgement behind [`TriggerBox::device_to_host_ns`]: the
    /// bound on its error (ns).
    pub fn clock_uncertainty_ns(&self) -> Option<u64> {
        match self.shared.offset_rtt_ns.load(Ordering::Acquire) {
            u64::MAX => None,
            rtt => Some(rtt / 2),
        }
    }

    /// Fire reports dropped because nobody polled them.
    pub fn fired_dropped(&self) -> u64 {
        self.shared.fired_dropped.load(Ordering::Relaxed)
    }

    /// Healthy, or the sticky fault; a task that ended unasked (its runtime was shut down) is the
    /// fault [`Fault::TaskEnded`].
    fn check(&self) -> Result<(), SerialError> {
        if self.shared.task_ended.load(Ordering::Acquire)
            && !self.shared.stopping.load(Ordering::Acquire)
        {
            self.shared.health.trip(Fault::TaskEnded);
        }
        self.shared.health.check()
    }

    fn queue(&self, cmd: Command) -> Result<(), SerialError> {
        self.check()?;
        if self.shared.commands.push(cmd).is_err() {
            self.shared.health.trip(Fault::QueueFull);
            return Err(Fault::QueueFull.into());
        }
        Ok(())
    }
}

impl ErrorType for TriggerBox {
    type Error = SerialError;
}

impl Lifecycle for TriggerBox {
    /// A fault the task tripped on: garbage, `E` line, missed ack, stale inputs, hang-up.
    fn health(&mut self) -> Result<(), SerialError> {
        self.check()
    }

    /// Write what is queued (a last level), wait for its acknowledgements (up to the ack
    /// timeout), close the port and end the task; every clone is stopped with it.
    fn stop(&mut self) -> Result<(), SerialError> {
        self.shared.stopping.store(true, Ordering::Release);
        let ended = match self._task.ended.lock() {
            Ok(end) => end.wait(self.stop_timeout),
            Err(_) => self.shared.task_ended.load(Ordering::Acquire),
        };
        if ended {
            Ok(())
        } else {
            self._task.task.abort();
            Err(SerialError::new(
                ErrorKind::Timeout,
                "trigger box: queued commands were not written in time; the task was aborted",
            ))
        }
    }
}

impl Trigger for TriggerBox {
    fn fire(&mut self, tick: u64, lines: TriggerLines) -> Result<(), SerialError> {
        if !lines.camera && !lines.light {
            return Err(SerialError::new(ErrorKind::InvalidRequest, "fire with no lines selected"));
        }
        self.queue(Command::Fire { tick, lines })
    }

    fn poll_fired(&mut self) -> Result<Option<FireReport>, SerialError> {
        // Deliver acks that arrived before a fault; then report the fault.
        if let Some(r) = self.shared.fired.pop() {
            return Ok(Some(r));
        }
        self.check()?;
        Ok(None)
    }
}

impl Inputs for TriggerBox {
    fn read(&mut self) -> Result<InputState, SerialError> {
        self.check()?;
        if !self.shared.inputs_fresh(self.shared.clock.now_ns()) {
            self.shared.health.trip(Fault::InputsStale);
            return Err(Fault::InputsStale.into());
        }
        let bits = self.shared.inputs.load(Ordering::Acquire);
        Ok(InputState { estop_pressed: bits & INPUT_ESTOP != 0, door_open: bits & INPUT_DOOR != 0 })
    }
}

impl Light for TriggerBox {
    fn set_level(&mut self, level: f32) -> Result<(), SerialError> {
        self.check()?;
        check_level(level)?;
        self.shared.level.store(u32::from(level_permille(level)), Ordering::Release);
        Ok(())
    }

    fn strobe(&mut self, level: f32, duration_us: u32) -> Result<(), SerialError> {
        check_level(level)?;
        if duration_us == 0 {
            return Err(SerialError::new(
                ErrorKind::InvalidRequest,
                "strobe duration must be positive",
            ));
        }
        self.queue(Command::Strobe { permille: level_permille(level), duration_us })
    }
}

/// A command written and waiting for its `A`.
struct Pending {
    seq: u32,
    fire_tick: Option<u64>,
    is_ping: bool,
    /// When the command's last byte was handed to the port.
    sent_ns: u64,
    deadline_ns: u64,
}

struct BoxTask {
    config: TriggerBoxConfig,
    shared: Arc<Shared>,
    pending: VecDeque<Pending>,
    next_seq: u32,
    sent_level: u32,
    /// When the current clock-offset estimate was made.
    offset_at_ns: u64,
}

/// A clock-offset estimate older than this is replaced by the next one, however long its round
/// trip (the box's crystal drifts against the host's clock).
const OFFSET_MAX_AGE_NS: u64 = 1_000_000_000;

impl BoxTask {
    fn seq(&mut self) -> u32 {
        let s = self.next_seq;
        self.next_seq = self.next_seq.checked_add(1).unwrap_or(1);
        s
    }

    fn on_line(&mut self, line: &[u8]) -> Result<(), Fault> {
        let now = self.shared.clock.now_ns();
        match parse_line(line).map_err(|_| Fault::Garbage)? {
            BoxLine::Ack { seq, device_us } => {
                let i =
                    self.pending.iter().position(|p| p.seq == seq).ok_or(Fault::UnexpectedAck)?;
                let p = self.pending.remove(i).ok_or(Fault::UnexpectedAck)?;
                self.update_offset(p.sent_ns, now, device_us);
                if p.is_ping {
                    self.shared.ping_acked.store(true, Ordering::Release);
                    self.shared.open_progress.notify_one();
                }
                if let Some(tick) = p.fire_tick {
                    let report = FireReport { tick, device_us, acked_ns: now };
                    if self.shared.fired.force_push(report).is_some() {
                        self.shared.fired_dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            BoxLine::Inputs { estop_pressed, door_open, .. } => {
                let bits = INPUT_VALID
                    | if estop_pressed { INPUT_ESTOP } else { 0 }
                    | if door_open { INPUT_DOOR } else { 0 };
                self.shared.inputs.store(bits, Ordering::Release);
                self.shared.inputs_at_ns.store(now, Ordering::Release);
                self.shared.open_progress.notify_one();
            }
            BoxLine::Error { .. } => return Err(Fault::BoxError),
        }
        Ok(())
    }

    /// Cristian's estimate: the box stamped its ack around the middle of the round trip.
    fn update_offset(&mut self, sent_ns: u64, acked_ns: u64, device_us: u64) {
        let rtt = acked_ns.saturating_sub(sent_ns);
        let best = self.shared.offset_rtt_ns.load(Ordering::Acquire);
        if rtt <= best || acked_ns.saturating_sub(self.offset_at_ns) > OFFSET_MAX_AGE_NS {
            let mid = i128::from(sent_ns) + i128::from(rtt / 2);
            let off = mid - i128::from(device_us) * 1000;
            let off = i64::try_from(off).unwrap_or(if off < 0 { i64::MIN } else { i64::MAX });
            self.shared.offset_ns.store(off, Ordering::Release);
            self.shared.offset_rtt_ns.store(rtt, Ordering::Release);
            self.offset_at_ns = acked_ns;
        }
    }

    async fn write_command<W>(&mut self, w: &mut W, cmd: Command) -> Result<(), Fault>
    where
        W: tokio::io::AsyncWrite + Unpin,
    {
        if self.pending.len() >= self.config.queue {
            return Err(Fault::QueueFull);
        }
        let seq = self.seq();
        let line = format_command(seq, cmd);
        write_within(w, line.as_bytes(), self.config.write_timeout).await?;
        let ack_ns = u64::try_from(self.config.ack_timeout.as_nanos()).unwrap_or(u64::MAX);
        let sent_ns = self.shared.clock.now_ns();
        self.pending.push_back(Pending {
            seq,
            fire_tick: match cmd {
                Command::Fire { tick, .. } => Some(tick),
                _ => None,
            },
            is_ping: cmd == Command::Ping,
            sent_ns,
            deadline_ns: sent_ns.saturating_add(ack_ns),
        });
        Ok(())
    }

    /// Write queued commands and a changed level; check deadlines.
    async fn service<W>(&mut self, w: &mut W) -> Result<(), Fault>
    where
        W: tokio::io::AsyncWrite + Unpin,
    {
        while let Some(cmd) = self.shared.commands.pop() {
            self.write_command(w, cmd).await?;
        }
        let level = self.shared.level.load(Ordering::Acquire);
        if level != LEVEL_UNSET && level != self.sent_level {
            let permille = u16::try_from(level).unwrap_or(1000);
            self.write_command(w, Command::Level { permille }).await?;
            self.sent_level = level;
        }
        let now = self.shared.clock.now_ns();
        if self.pending.front().is_some_and(|p| now > p.deadline_ns) {
            return Err(Fault::AckTimeout);
        }
        // Staleness counts only once the box has reported at least once (open waits for that).
        if self.shared.inputs.load(Ordering::Acquire) & INPUT_VALID != 0
            && !self.shared.inputs_fresh(now)
        {
            return Err(Fault::InputsStale);
        }
        Ok(())
    }
}

async fn box_task(
    port: tokio_serial::SerialStream,
    config: TriggerBoxConfig,
    shared: Arc<Shared>,
    _mark: EndMark,
) {
    let (mut rd, mut wr) = tokio::io::split(port);
    let mut task = BoxTask {
        config,
        shared: Arc::clone(&shared),
        pending: VecDeque::with_capacity(config.queue),
        next_seq: 1,
        sent_level: LEVEL_UNSET,
        offset_at_ns: 0,
    };
    let mut lines = LineBuffer::new();
    let mut chunk = [0u8; 256];
    let mut poll = tokio::time::interval(config.poll);
    poll.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let result: Result<(), Fault> = loop {
        tokio::select! {
            r = rd.read(&mut chunk) => {
                let n = match r {
                    Ok(0) => break Err(Fault::Unplugged),
                    Ok(n) => n,
                    Err(e) => break Err(classify_io(&e)),
                };
                let mut res = Ok(());
                for &b in &chunk[..n] {
                    match lines.push(b) {
                        Pushed::Partial => {}
                        Pushed::TooLong => { res = Err(Fault::LineTooLong); break; }
                        Pushed::Line(l) => {
                            let r = task.on_line(l);
                            lines.clear();
                            if r.is_err() { res = r; break; }
                        }
                    }
                }
                if let Err(f) = res { break Err(f); }
            }
            _ = poll.tick() => {
                let stopping = shared.stopping.load(Ordering::Acquire);
                if let Err(f) = task.service(&mut wr).await { break Err(f); }
                // Stopping: once what was queued is written and acknowledged (or its ack
                // deadline has tripped a fault), so that no late `A` is left for the next opener.
                if stopping && task.pending.is_empty() { break Ok(()); }
            }
        }
    };
    if let Err(f) = result {
        shared.health.trip(f);
        shared.open_progress.notify_one();
    }
}
