//! The microcontroller trigger box on a serial line: camera trigger and light strobe lines,
//! a dimmable light output, and the enclosure's safety inputs (e-stop, door). Protocol version 2.
//!
//! Protocol: docs/trigger-box-protocol.md, codec in [`super::protocol`]. The tick-side handle
//! ([`TriggerBox`], cheap to clone) only touches atomics and lock-free queues; a tokio task owns
//! the port, writes queued commands, matches answers to commands, keeps the latest input report,
//! keeps the box's clock mapped onto the host's ([`super::clock_map`]), sends a keep-alive `P`
//! when nothing else was written for 250 ms, resends a command the box was too busy for (`E <seq>
//! 3`, counted, never a fault), and enforces the deadlines (answer, input staleness, write). Any
//! fault (garbage, over-long line, unexpected answer, another `E` line, a restart banner,
//! timeout, hang-up) is sticky and returned by the next call from the tick.
//!
//! Opening (host-side rules in the protocol doc): the port's input is flushed; nothing is written
//! until a first whole line came from the box (the bytes up to the first `\n` are dropped: a
//! partial line), for up to `start_timeout` (2 s), which covers an Arduino that resets when its
//! port is opened and sits in its bootloader meanwhile; then `\n` (ends whatever partial line the
//! box holds), `P` and `V`. `open` returns once the ping is answered, the box said it speaks
//! protocol 2, and its inputs are known.
//!
//! The task runs on the run's tokio runtime for as long as any clone is in use (the runtime must
//! outlive the handles); [`Lifecycle::stop`] has it write what is queued, close the port and end.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use crossbeam_queue::ArrayQueue;
use hitl_hal::{
    Clock, ErrorKind, ErrorType, FireReport, InputState, Inputs, Lifecycle, Light, MonotonicClock,
    Trigger, TriggerLines,
};
use tokio::io::AsyncReadExt;
use tokio::task::JoinHandle;
use tokio_serial::SerialPort as _;

use super::clock_map::{ClockFit, Mapping, MappingCell, Sample};
use super::fault::{Fault, Health, SerialError, TaskAlive, TaskEnd};
use super::protocol::{
    format_command, level_permille, parse_line, BoxLine, Command, FirmwareVersion, LineBuffer,
    Notice, Pushed, ResetCause, ERR_BUSY, ERR_UNKNOWN, PROTOCOL_VERSION,
};
use super::serial::{check_level, classify_io, open_port, write_within};

/// Settings of a trigger box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriggerBoxConfig {
    pub baud: u32,
    /// A command not answered within this is a fault.
    pub ack_timeout: Duration,
    /// Input reports older than this are a fault (the box sends them at least every 50 ms).
    pub inputs_stale_after: Duration,
    /// How often the task looks at the command queue and the deadlines.
    pub poll: Duration,
    pub write_timeout: Duration,
    /// After the box's first line, `open` waits this long for the ping's answer, the version and
    /// the first input report.
    pub open_timeout: Duration,
    /// How long `open` waits for the box's first line before writing anything: a running box
    /// reports its inputs every 20 ms; an Uno or Nano that resets when its port is opened sends
    /// its banner once its bootloader has given up (1 to 2 s).
    pub start_timeout: Duration,
    /// Commands that may wait for the port (and answers that may be outstanding).
    pub queue: usize,
    /// A `P` is written when nothing else was for this long (the box goes to its fail-safe after
    /// 1 s without a command).
    pub keepalive: Duration,
    /// A fire or flash the box was busy for (`E <seq> 3`) is sent again as long as this has not
    /// passed since it was first sent (one tick at 250 Hz); then it is given up (counted).
    pub busy_retry_for: Duration,
    /// One byte's time on the box's UART (10 bits at 115200 baud): the round trips that map the
    /// box's clock take the bytes' time off. Zero for a box on native USB (no UART in between).
    pub byte_time: Duration,
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
            start_timeout: Duration::from_secs(2),
            queue: 32,
            keepalive: Duration::from_millis(250),
            busy_retry_for: Duration::from_millis(4),
            byte_time: Duration::from_nanos(86_806),
        }
    }
}

/// What the box said of itself (`V`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoxVersion {
    pub protocol: u16,
    pub firmware: FirmwareVersion,
}

/// Commands the box was too busy for (`E <seq> 3`, or `E 0 3` for one it dropped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusyCounts {
    /// Busy answers received.
    pub answers: u64,
    /// Commands sent again after one.
    pub retried: u64,
    /// Commands given up (a fire or flash still busy after `busy_retry_for`).
    pub given_up: u64,
}

const INPUT_VALID: u8 = 1;
const INPUT_ESTOP: u8 = 2;
const INPUT_DOOR: u8 = 4;
const LEVEL_UNSET: u32 = u32::MAX;
/// Sendings of one command at most (the first and three retries).
const MAX_TRIES: u8 = 4;

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
    /// A whole line has come from the box since the port was opened.
    started: AtomicBool,
    ping_acked: AtomicBool,
    version: OnceLock<BoxVersion>,
    /// The box answered `V` with "unknown command" (a protocol-1 box).
    version_refused: AtomicBool,
    /// The box's clock on the host's.
    mapping: MappingCell,
    /// The reset cause of a restart banner after opening (`ResetCause as u8 + 1`; 0 none).
    restart: AtomicU8,
    busy_answers: AtomicU64,
    busy_retried: AtomicU64,
    busy_given_up: AtomicU64,
    keepalives: AtomicU64,
    /// `# safe host-silent` notices after opening (the level is sent again after one).
    host_silent: AtomicU64,
    /// Asked to write what is queued and end.
    stopping: AtomicBool,
    /// The task has ended (set by its drop guard, also when it is aborted).
    task_ended: AtomicBool,
    /// Wakes `open` on a first line, the ping's answer, the version, an input report or a fault.
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

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

impl TriggerBox {
    /// Open the box at `path` (docs/trigger-box-protocol.md, "Host side"): wait for its first
    /// line (`start_timeout`), then check within `open_timeout` that it answers a ping, speaks
    /// protocol 2 and reports its inputs. Stamps use `clock` (the controller's). Must run inside
    /// a tokio runtime.
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
        // What waited in the port before it was opened is not this session's.
        let _ = port.clear(tokio_serial::ClearBuffer::Input);
        let shared = Arc::new(Shared {
            health: Health::new(),
            clock,
            stale_ns: nanos(config.inputs_stale_after),
            commands: ArrayQueue::new(config.queue),
            fired: ArrayQueue::new(config.queue.max(64)),
            fired_dropped: AtomicU64::new(0),
            inputs: AtomicU8::new(0),
            inputs_at_ns: AtomicU64::new(0),
            level: AtomicU32::new(LEVEL_UNSET),
            started: AtomicBool::new(false),
            ping_acked: AtomicBool::new(false),
            version: OnceLock::new(),
            version_refused: AtomicBool::new(false),
            mapping: MappingCell::new(),
            restart: AtomicU8::new(0),
            busy_answers: AtomicU64::new(0),
            busy_retried: AtomicU64::new(0),
            busy_given_up: AtomicU64::new(0),
            keepalives: AtomicU64::new(0),
            host_silent: AtomicU64::new(0),
            stopping: AtomicBool::new(false),
            task_ended: AtomicBool::new(false),
            open_progress: tokio::sync::Notify::new(),
        });
        let _ = shared.commands.push(Command::Ping);
        let _ = shared.commands.push(Command::Version);
        let (alive, ended) = TaskEnd::new();
        let mark = EndMark { shared: Arc::clone(&shared), _alive: alive };
        let task = tokio::spawn(box_task(port, config, Arc::clone(&shared), mark));
        let tb = Self {
            shared,
            _task: Arc::new(TaskGuard { task, ended: std::sync::Mutex::new(ended) }),
            stop_timeout: config.write_timeout * 4 + config.ack_timeout + config.poll * 2,
        };
        // Until the box's first line: nothing is written meanwhile.
        let start_deadline = tokio::time::Instant::now() + config.start_timeout;
        let mut deadline = None;
        loop {
            if tb.shared.task_ended.load(Ordering::Acquire) {
                tb.shared.health.trip(Fault::TaskEnded);
            }
            if let Some(f) = tb.shared.health.fault() {
                return Err(tb.open_error(path, f));
            }
            let now = tokio::time::Instant::now();
            if !tb.shared.started.load(Ordering::Acquire) {
                if now >= start_deadline {
                    return Err(SerialError::new(
                        ErrorKind::Timeout,
                        format!(
                            "trigger box on {path}: not a line from it within {} ms of opening \
                             the port (is it the box, is its firmware flashed, is it powered?)",
                            config.start_timeout.as_millis()
                        ),
                    ));
                }
            } else {
                let until = *deadline.get_or_insert(now + config.open_timeout);
                if tb.shared.ping_acked.load(Ordering::Acquire)
                    && tb.shared.version.get().is_some_and(|v| v.protocol == PROTOCOL_VERSION)
                    && tb.shared.inputs_fresh(tb.shared.clock.now_ns())
                {
                    return Ok(tb);
                }
                if now >= until {
                    return Err(SerialError::new(
                        ErrorKind::Timeout,
                        format!(
                            "trigger box on {path}: no answer to the ping and the version \
                             request and no input report within {} ms",
                            config.open_timeout.as_millis()
                        ),
                    ));
                }
            }
            let until = deadline.unwrap_or(start_deadline);
            // A stored permit covers progress made since the checks above.
            let _ = tokio::time::timeout_at(until, tb.shared.open_progress.notified()).await;
        }
    }

    /// The error `open` returns for a fault, naming the port and, for a version mismatch, both
    /// versions.
    fn open_error(&self, path: &str, f: Fault) -> SerialError {
        let msg = match (f, self.shared.version.get()) {
            (Fault::WrongProtocol, Some(v)) => format!(
                "trigger box on {path} speaks protocol {} (firmware {}); this driver speaks \
                 protocol {PROTOCOL_VERSION}: flash firmware/trigger-box (docs/trigger-box.md)",
                v.protocol, v.firmware
            ),
            (Fault::WrongProtocol, None) => format!(
                "trigger box on {path} does not know the V command (a protocol-1 firmware); this \
                 driver speaks protocol {PROTOCOL_VERSION}: flash firmware/trigger-box \
                 (docs/trigger-box.md)"
            ),
            (f, _) => format!("trigger box on {path}: {} while opening", f.message()),
        };
        SerialError::new(f.kind(), msg)
    }

    /// The fault the driver tripped on, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.shared.health.fault()
    }

    /// The box's protocol and firmware versions (known once `open` has returned).
    pub fn version(&self) -> Option<BoxVersion> {
        self.shared.version.get().copied()
    }

    /// Why the box restarted, when its banner came after it was opened (the fault
    /// [`Fault::BoxRestarted`]).
    pub fn restart_cause(&self) -> Option<ResetCause> {
        const CAUSES: [ResetCause; 5] = [
            ResetCause::Power,
            ResetCause::External,
            ResetCause::Brownout,
            ResetCause::Watchdog,
            ResetCause::Unknown,
        ];
        let code = self.shared.restart.load(Ordering::Acquire);
        CAUSES.get(usize::from(code).checked_sub(1)?).copied()
    }

    /// The box's clock on the host's, as fitted so far (`None` before the first answer).
    pub fn clock_mapping(&self) -> Option<Mapping> {
        self.shared.mapping.load()
    }

    /// The box's time `device_us` on the controller's clock (ns), from the clock mapping (offset
    /// and drift fitted over the answers' round trips); `None` before the first answer.
    pub fn device_to_host_ns(&self, device_us: u64) -> Option<u64> {
        self.clock_mapping().map(|m| m.host_ns(device_us))
    }

    /// A bound on [`TriggerBox::device_to_host_ns`]'s error at the newest answer's time (ns); it
    /// grows with the distance from the answers by the drift's uncertainty
    /// ([`Mapping::error_ns`]).
    pub fn clock_uncertainty_ns(&self) -> Option<u64> {
        self.clock_mapping().map(|m| m.error_ns(m.newest_device_ns / 1000))
    }

    /// Fire reports dropped because nobody polled them.
    pub fn fired_dropped(&self) -> u64 {
        self.shared.fired_dropped.load(Ordering::Relaxed)
    }

    /// Busy answers, the commands sent again and those given up.
    pub fn busy(&self) -> BusyCounts {
        BusyCounts {
            answers: self.shared.busy_answers.load(Ordering::Relaxed),
            retried: self.shared.busy_retried.load(Ordering::Relaxed),
            given_up: self.shared.busy_given_up.load(Ordering::Relaxed),
        }
    }

    /// Keep-alive pings written (nothing else was written for `keepalive`).
    pub fn keepalives_sent(&self) -> u64 {
        self.shared.keepalives.load(Ordering::Relaxed)
    }

    /// `# safe host-silent` notices since opening (each is followed by the level again).
    pub fn host_silent_notices(&self) -> u64 {
        self.shared.host_silent.load(Ordering::Relaxed)
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
}

impl TriggerBox {
    /// Flash the light at `level` for `duration_us` microseconds, now (the box's `S` command).
    /// Not part of the hal's `Light`: a run flashes with its captures through the strobe line
    /// ([`Trigger::fire`]), timed by the box. Kept as the box's own command.
    pub fn strobe(&mut self, level: f32, duration_us: u32) -> Result<(), SerialError> {
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

/// A command written and waiting for its answer.
struct Pending {
    seq: u32,
    cmd: Command,
    /// When the write of its line began, and the line's length (for the clock's samples).
    sent_ns: u64,
    bytes: usize,
    deadline_ns: u64,
    /// When it was first sent (a busy command keeps it), and how often.
    first_ns: u64,
    tries: u8,
}

/// A command to send again (the box was busy for it).
struct Retry {
    cmd: Command,
    first_ns: u64,
    tries: u8,
}

struct BoxTask {
    config: TriggerBoxConfig,
    shared: Arc<Shared>,
    pending: VecDeque<Pending>,
    retry: VecDeque<Retry>,
    next_seq: u32,
    sent_level: u32,
    /// `\n` has been written after the box's first line (and the queued `P`, `V` may go).
    greeted: bool,
    /// When a command was last written.
    last_write_ns: u64,
    /// `E 0 3` lines not yet matched to the command the box dropped.
    drops_announced: u32,
    clock: ClockFit,
}

impl BoxTask {
    fn seq(&mut self) -> u32 {
        let s = self.next_seq;
        self.next_seq = self.next_seq.checked_add(1).unwrap_or(1);
        s
    }

    fn byte_ns(&self) -> u64 {
        nanos(self.config.byte_time)
    }

    /// One line from the box (without its `\n`).
    fn on_line(&mut self, line: &[u8]) -> Result<(), Fault> {
        let now = self.shared.clock.now_ns();
        let parsed = parse_line(line).map_err(|_| Fault::Garbage)?;
        if !self.shared.started.swap(true, Ordering::AcqRel) {
            self.shared.open_progress.notify_one();
        }
        let opened = self.shared.ping_acked.load(Ordering::Acquire);
        match parsed {
            BoxLine::Ack { seq, device_us } => {
                let p = self.answered(seq)?;
                self.answer(&p, device_us, now, line.len() + 1);
            }
            BoxLine::Version { seq, device_us, protocol, firmware } => {
                let p = self.answered(seq)?;
                self.answer(&p, device_us, now, line.len() + 1);
                if protocol != PROTOCOL_VERSION {
                    // Tripped before the version is shown, so that `open` never takes it.
                    self.shared.health.trip(Fault::WrongProtocol);
                }
                let _ = self.shared.version.set(BoxVersion { protocol, firmware });
                self.shared.open_progress.notify_one();
                if protocol != PROTOCOL_VERSION {
                    return Err(Fault::WrongProtocol);
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
            BoxLine::Error { seq: 0, code: ERR_BUSY } => {
                // The box dropped a command (its queue was full): the oldest one left
                // unanswered, found when a later one is answered or its deadline passes.
                self.shared.busy_answers.fetch_add(1, Ordering::Relaxed);
                self.drops_announced = self.drops_announced.saturating_add(1);
            }
            BoxLine::Error { seq, code: ERR_BUSY } => {
                self.shared.busy_answers.fetch_add(1, Ordering::Relaxed);
                let p = self.answered(seq)?;
                self.busy(p.cmd, p.first_ns, p.tries, now);
            }
            BoxLine::Error { seq, code: ERR_UNKNOWN }
                if self.pending.iter().any(|p| p.seq == seq && p.cmd == Command::Version) =>
            {
                self.shared.version_refused.store(true, Ordering::Release);
                return Err(Fault::WrongProtocol);
            }
            BoxLine::Error { .. } => return Err(Fault::BoxError),
            BoxLine::Notice(Notice::Banner { reset, .. }) => {
                // Before the ping's answer: the box starting (or reset by the port's opening).
                if opened {
                    self.shared.restart.store(reset as u8 + 1, Ordering::Release);
                    return Err(Fault::BoxRestarted);
                }
            }
            BoxLine::Notice(Notice::HostSilent) => {
                // The box went safe (light off): the level goes out again at the next poll.
                if opened {
                    self.shared.host_silent.fetch_add(1, Ordering::Relaxed);
                    self.sent_level = LEVEL_UNSET;
                }
            }
            BoxLine::Notice(Notice::Other) => {}
        }
        Ok(())
    }

    /// Take the pending command `seq` answers. The box answers in the order it was sent, so the
    /// commands before it were dropped, if the box said it dropped some (`E 0 3`): those are sent
    /// again.
    fn answered(&mut self, seq: u32) -> Result<Pending, Fault> {
        let i = self.pending.iter().position(|p| p.seq == seq).ok_or(Fault::UnexpectedAck)?;
        let now = self.shared.clock.now_ns();
        for _ in 0..i {
            if self.drops_announced == 0 {
                break;
            }
            self.drops_announced -= 1;
            if let Some(p) = self.pending.pop_front() {
                self.busy(p.cmd, p.first_ns, p.tries, now);
            }
        }
        let i = self.pending.iter().position(|p| p.seq == seq).ok_or(Fault::UnexpectedAck)?;
        self.pending.remove(i).ok_or(Fault::UnexpectedAck)
    }

    /// A command the box was busy for: send it again, or give it up (a fire or a flash whose
    /// moment has passed).
    fn busy(&mut self, cmd: Command, first_ns: u64, tries: u8, now: u64) {
        let timely = match cmd {
            Command::Fire { .. } | Command::Strobe { .. } => {
                now.saturating_sub(first_ns) <= nanos(self.config.busy_retry_for)
            }
            _ => true,
        };
        if timely && tries < MAX_TRIES {
            self.retry.push_back(Retry { cmd, first_ns, tries });
            self.shared.busy_retried.fetch_add(1, Ordering::Relaxed);
        } else {
            self.shared.busy_given_up.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// An `A` or `V` for `p`: a clock sample, and what the command was for.
    fn answer(&mut self, p: &Pending, device_us: u64, now: u64, answer_bytes: usize) {
        let byte_ns = self.byte_ns();
        let sample = Sample::new(device_us, p.sent_ns, p.bytes, now, answer_bytes, byte_ns);
        if let Some(s) = sample {
            if let Some(m) = self.clock.add(s) {
                self.shared.mapping.store(&m);
            }
        }
        if p.cmd == Command::Ping {
            self.shared.ping_acked.store(true, Ordering::Release);
            self.shared.open_progress.notify_one();
        }
        if let Command::Fire { tick, .. } = p.cmd {
            // The fit's time for the pulse, held to the fire's own round trip.
            let fitted = self
                .clock
                .mapping()
                .map(|m| m.host_ns(device_us))
                .zip(self.clock.error_ns(device_us));
            let host = match (fitted, sample) {
                (Some((h, e)), Some(s)) => Some(s.hold(h, e)),
                (fitted, _) => fitted,
            };
            let report = FireReport {
                tick,
                device_us,
                acked_ns: now,
                host_ns: host.map(|h| h.0),
                host_error_ns: host.map(|h| h.1),
            };
            if self.shared.fired.force_push(report).is_some() {
                self.shared.fired_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    async fn write_command<W>(
        &mut self,
        w: &mut W,
        cmd: Command,
        first: Option<(u64, u8)>,
    ) -> Result<(), Fault>
    where
        W: tokio::io::AsyncWrite + Unpin,
    {
        if self.pending.len() >= self.config.queue {
            return Err(Fault::QueueFull);
        }
        let seq = self.seq();
        let line = format_command(seq, cmd);
        let sent_ns = self.shared.clock.now_ns();
        write_within(w, line.as_bytes(), self.config.write_timeout).await?;
        self.last_write_ns = self.shared.clock.now_ns();
        let (first_ns, tries) = first.unwrap_or((sent_ns, 0));
        self.pending.push_back(Pending {
            seq,
            cmd,
            sent_ns,
            bytes: line.len(),
            deadline_ns: self.last_write_ns.saturating_add(nanos(self.config.ack_timeout)),
            first_ns,
            tries: tries.saturating_add(1),
        });
        Ok(())
    }

    /// Write what the box was busy for, queued commands, a changed level and a keep-alive; check
    /// deadlines.
    async fn service<W>(&mut self, w: &mut W) -> Result<(), Fault>
    where
        W: tokio::io::AsyncWrite + Unpin,
    {
        // Nothing is written before the box's first line (it may be in its bootloader).
        if !self.shared.started.load(Ordering::Acquire) {
            return Ok(());
        }
        if !self.greeted {
            write_within(w, b"\n", self.config.write_timeout).await?;
            self.greeted = true;
        }
        let now = self.shared.clock.now_ns();
        while let Some(r) = self.retry.pop_front() {
            if matches!(r.cmd, Command::Fire { .. } | Command::Strobe { .. })
                && now.saturating_sub(r.first_ns) > nanos(self.config.busy_retry_for)
            {
                self.shared.busy_given_up.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            self.write_command(w, r.cmd, Some((r.first_ns, r.tries))).await?;
        }
        while let Some(cmd) = self.shared.commands.pop() {
            self.write_command(w, cmd, None).await?;
        }
        let level = self.shared.level.load(Ordering::Acquire);
        if level != LEVEL_UNSET && level != self.sent_level {
            let permille = u16::try_from(level).unwrap_or(1000);
            self.write_command(w, Command::Level { permille }, None).await?;
            self.sent_level = level;
        }
        let now = self.shared.clock.now_ns();
        if !self.shared.stopping.load(Ordering::Acquire)
            && now.saturating_sub(self.last_write_ns) >= nanos(self.config.keepalive)
        {
            self.write_command(w, Command::Ping, None).await?;
            self.shared.keepalives.fetch_add(1, Ordering::Relaxed);
        }
        while self.pending.front().is_some_and(|p| now > p.deadline_ns) {
            // Unanswered: the command the box said it dropped, or a box that stopped answering.
            if self.drops_announced == 0 {
                return Err(Fault::AckTimeout);
            }
            self.drops_announced -= 1;
            if let Some(p) = self.pending.pop_front() {
                self.busy(p.cmd, p.first_ns, p.tries, now);
            }
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
        retry: VecDeque::new(),
        next_seq: 1,
        sent_level: LEVEL_UNSET,
        greeted: false,
        last_write_ns: 0,
        drops_announced: 0,
        clock: ClockFit::new(),
    };
    let mut lines = LineBuffer::new();
    // The bytes before the first `\n` are the end of a line begun before the port was opened.
    let mut partial = true;
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
                    if partial {
                        partial = b != b'\n';
                        continue;
                    }
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
                // Stopping: once what was queued is written and answered (or its deadline has
                // tripped a fault), so that no late answer is left for the next opener.
                if stopping && task.pending.is_empty() && task.retry.is_empty() { break Ok(()); }
            }
        }
    };
    if let Err(f) = result {
        shared.health.trip(f);
        shared.open_progress.notify_one();
    }
}
