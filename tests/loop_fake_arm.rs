//! The control loop against an in-process arm that follows every command exactly: the loop's
//! logic on its own (phases, trips, stops), and the proof that the tick allocates and frees
//! nothing, with the fake arm and with the real `XarmClient` talking to the stub's protocol
//! server. (End-to-end runs against the MuJoCo stub are in `run_stub.rs`.)

use hitl::control::correction::{CorrectionQueues, CorrectionSegment, CorrectionStage};
use hitl::control::interlocks::{Interlocks, Thresholds};
use hitl::control::motion::{plan_move, MoveLimits};
use hitl::control::stop::StopPlanner;
use hitl::control::tick::{ControlLoop, Devices, Health, LoopIo, Outcome, Program};
use hitl::devices::none::{NoCamera, NoInputs, NoLight, NoTrigger};
use hitl::rt::probe;
use hitl::rt::slot::LatestSlot;
use hitl::telemetry::TripKind;
use hitl::telemetry::{LoopStatus, NoTelemetry};
use hitl_hal::JointState;
use hitl_hal::{
    Arm, ArmState, CaptureRequest, Clock, ErrorKind, ErrorType, FireReport, Intrinsics, Joints,
    Lifecycle, MonotonicClock, RgbdCamera, RgbdFrame, StreamConfig, Trigger, TriggerLines,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Counts allocations and frees made on a thread while it is inside the real-time loop.
struct CountingAllocator;

static RT_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
static RT_FREES: AtomicU64 = AtomicU64::new(0);

// SAFETY: delegates to the system allocator unchanged; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if probe::in_rt_loop() {
            RT_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if probe::in_rt_loop() {
            RT_FREES.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if probe::in_rt_loop() {
            RT_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// What the fake arm does at a given command count.
#[derive(Clone, Copy, Default)]
struct Script {
    /// After this many commands, offset joint 3's report by 0.2 rad.
    deviate_after: Option<usize>,
    /// After this many commands, the connection fails.
    disconnect_after: Option<usize>,
    /// After this many commands, the arm stops answering (the connection stays open).
    unanswered_after: Option<usize>,
}

struct FakeArm {
    sent: Vec<Joints>,
    reports: LatestSlot<ArmState>,
    script: Script,
    stopped: bool,
    clock: MonotonicClock,
    feed: Option<Feed>,
}

/// A navigator that hands its segments over on the loop's own ticks (from the fake arm's
/// `servo_joint`), each once the one before it has taken effect: the same tick whatever the
/// machine's load. Moving a built segment into the queue neither allocates nor frees.
struct Feed {
    queues: CorrectionQueues,
    segments: std::collections::VecDeque<CorrectionSegment>,
    /// The segment that must be in effect before the next is handed over (0: none).
    after: u64,
}

impl Feed {
    fn hand_over(&mut self) {
        if self.queues.stats.active.load(Ordering::Relaxed) != self.after {
            return;
        }
        if let Some(seg) = self.segments.pop_front() {
            self.after = seg.id;
            self.queues.incoming.push(seg).expect("room");
        }
    }
}

impl ErrorType for FakeArm {
    type Error = ErrorKind;
}

impl Arm for FakeArm {
    fn enable_servo(&mut self) -> Result<(), ErrorKind> {
        Ok(())
    }
    fn servo_joint(&mut self, q: &Joints) -> Result<(), ErrorKind> {
        if self.script.disconnect_after.is_some_and(|n| self.sent.len() >= n) {
            return Err(ErrorKind::Disconnected);
        }
        if self.script.unanswered_after.is_some_and(|n| self.sent.len() >= n) {
            return Err(ErrorKind::Timeout);
        }
        self.sent.push(*q);
        if let Some(feed) = self.feed.as_mut() {
            feed.hand_over();
        }
        let mut measured = *q;
        if self.script.deviate_after.is_some_and(|n| self.sent.len() >= n) {
            measured[3] += 0.2;
        }
        self.reports.publish(ArmState {
            received_ns: self.clock.now_ns(),
            q: measured,
            seq: self.sent.len() as u64,
            ..Default::default()
        });
        Ok(())
    }
    fn stop(&mut self) -> Result<(), ErrorKind> {
        self.stopped = true;
        Ok(())
    }
    fn joint_positions(&mut self) -> Result<Joints, ErrorKind> {
        Ok(self.sent.last().copied().unwrap_or([0.0; 7]))
    }
    fn codes(&mut self) -> Result<(u8, u8), ErrorKind> {
        Ok((0, 0))
    }
}

const RATE: f64 = 250.0;
const START: Joints = [0.0, 0.3, 0.0, 1.2, 0.0, 0.9, 0.0];

/// A 1 s playback: joint 1 swings 0.1 rad and back, beginning 0.05 rad from the start pose.
fn program() -> Program {
    let dt = 1.0 / RATE;
    let mut first = START;
    first[0] = 0.05;
    let approach =
        plan_move(&START, &first, &MoveLimits::uniform(0.3, 0.8, 8.0), dt).expect("approach");
    let playback: Vec<JointState> = (0..250)
        .map(|k| {
            let t = k as f64 * dt;
            let mut q = first;
            q[0] = 0.05 + 0.05 * (1.0 - (std::f64::consts::PI * t).cos());
            let mut sp = JointState::rest(q);
            sp.qd[0] = 0.05 * std::f64::consts::PI * (std::f64::consts::PI * t).sin();
            sp
        })
        .collect();
    let n = playback.len();
    Program {
        approach,
        playback,
        capture: (0..n).map(|i| i % 50 == 0).collect(),
        light: vec![1.0; n],
        light_lead_ticks: 2,
        settle_tolerance_rad: 1e-3,
        settle_max_ticks: 50,
        ..Program::default()
    }
}

struct Ran {
    outcome: Outcome,
    sent: Vec<Joints>,
    stopped: bool,
    allocations: u64,
    frees: u64,
}

fn run(program: &Program, script: Script, operator_stop_at: Option<u64>) -> Ran {
    run_with(program, script, operator_stop_at, CorrectionStage::open_loop(), None)
}

/// [`run`] with a correction stage, and segments a navigator hands over while the loop runs:
/// each once the one before it has taken effect ([`Feed`]).
fn run_with(
    program: &Program,
    script: Script,
    operator_stop_at: Option<u64>,
    correction: CorrectionStage,
    feed: Option<(CorrectionQueues, Vec<CorrectionSegment>)>,
) -> Ran {
    run_with_lines(program, script, operator_stop_at, correction, feed, NoCamera, NoTrigger)
}

/// [`run_with`] with the run's camera and trigger lines.
fn run_with_lines<C: RgbdCamera + Lifecycle, G: Trigger + Lifecycle>(
    program: &Program,
    script: Script,
    operator_stop_at: Option<u64>,
    correction: CorrectionStage,
    feed: Option<(CorrectionQueues, Vec<CorrectionSegment>)>,
    camera: C,
    trigger: G,
) -> Ran {
    let feed = feed.map(|(queues, segments)| Feed { queues, segments: segments.into(), after: 0 });
    let clock = MonotonicClock::new();
    let (slot, reports) = LatestSlot::new();
    slot.publish(ArmState { received_ns: clock.now_ns(), q: START, ..Default::default() });
    let mut arm = FakeArm {
        sent: Vec::with_capacity(10_000),
        reports: slot,
        script,
        stopped: false,
        clock: clock.clone(),
        feed,
    };
    let health = Health::default();
    let status = Arc::new(LoopStatus::default());
    let limits = MoveLimits::uniform(1.0, 4.0, 60.0);
    let (_planner, stop) = StopPlanner::start(limits, 1.0 / RATE, 5.0).expect("planner");
    // The fake arm reports from inside the tick: a loop thread the machine stalls for a while
    // must not read as a silent arm (no test here is about the report watchdog).
    let interlocks = Interlocks::new(Thresholds {
        report_timeout_ns: 1_000_000_000,
        max_deviation_rad: 0.08,
        trip_on_warning: true,
        reply_stall_ns: 250_000_000,
    });
    if let Some(at) = operator_stop_at {
        let (flag, status) = (Arc::clone(&health.operator_stop), Arc::clone(&status));
        std::thread::spawn(move || {
            while status.tick.load(Ordering::Relaxed) < at {
                std::thread::sleep(Duration::from_millis(1));
            }
            flag.store(true, Ordering::Relaxed);
        });
    }
    let devices = Devices { arm: &mut arm, camera, light: NoLight, inputs: NoInputs, trigger };
    let io = LoopIo { reports, telemetry: NoTelemetry, status, health, stop, clock };
    let control = ControlLoop::new(program, devices, io, interlocks, RATE, &START)
        .with_correction(correction);
    let before = (RT_ALLOCATIONS.load(Ordering::Relaxed), RT_FREES.load(Ordering::Relaxed));
    let outcome = control.run(Duration::ZERO);
    let allocations = RT_ALLOCATIONS.load(Ordering::Relaxed) - before.0;
    let frees = RT_FREES.load(Ordering::Relaxed) - before.1;
    Ran { outcome, sent: arm.sent, stopped: arm.stopped, allocations, frees }
}

static SERIAL: AtomicBool = AtomicBool::new(false);

/// The allocation counter is process-wide: run these tests one at a time.
fn serial() -> impl Drop {
    struct Release;
    impl Drop for Release {
        fn drop(&mut self) {
            SERIAL.store(false, Ordering::Release);
        }
    }
    while SERIAL.compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire).is_err() {
        std::thread::sleep(Duration::from_millis(5));
    }
    Release
}

#[test]
fn the_counter_sees_an_allocation_and_a_free_on_the_loop_thread() {
    // The allocation tests below can fail: a Box made and dropped with the flag up counts.
    let _one = serial();
    let before = (RT_ALLOCATIONS.load(Ordering::Relaxed), RT_FREES.load(Ordering::Relaxed));
    {
        let _rt = probe::enter_rt_loop();
        drop(std::hint::black_box(Box::new([0u8; 64])));
    }
    assert_eq!(RT_ALLOCATIONS.load(Ordering::Relaxed) - before.0, 1);
    assert_eq!(RT_FREES.load(Ordering::Relaxed) - before.1, 1);
}

#[test]
fn a_whole_playback_sends_approach_then_trajectory_and_allocates_nothing() {
    let _one = serial();
    let p = program();
    let ran = run(&p, Script::default(), None);
    assert!(matches!(ran.outcome, Outcome::Completed { settled: true, .. }), "{:?}", ran.outcome);
    assert_eq!(ran.allocations, 0, "the tick allocated");
    assert_eq!(ran.frees, 0, "the tick freed");
    let expected: Vec<Joints> = p.approach.iter().chain(p.playback.iter()).map(|s| s.q).collect();
    assert_eq!(
        &ran.sent[..expected.len()],
        &expected[..],
        "setpoints are the program, bit for bit"
    );
    assert_eq!(ran.sent.last(), expected.last(), "settles on the last waypoint");
    assert!(!ran.stopped);
}

#[test]
fn closed_loop_corrections_are_added_in_the_playback_without_allocating() {
    let _one = serial();
    let p = program();
    let first = p.approach.len() as u64;
    // Two segments on joint 2: up to 0.004 rad and held, then a second continuing from it back
    // to zero (the navigator's shape, here written by hand).
    let up: Vec<JointState> = (0..40)
        .map(|i| {
            let mut s = JointState::default();
            s.q[1] = 0.004 * (i.min(20) as f64 / 20.0);
            s
        })
        .collect();
    let mut down: Vec<JointState> = (0..21)
        .map(|i| {
            let mut s = JointState::default();
            s.q[1] = 0.004 * (1.0 - i as f64 / 20.0);
            s
        })
        .collect();
    down[0] = up[30];
    let queues = CorrectionQueues::new(2);
    let (mut a, mut b) =
        (CorrectionSegment::with_capacity(64), CorrectionSegment::with_capacity(64));
    assert!(a.fill(1, 0, first + 10, &up));
    assert!(b.fill(2, 1, first + 40, &down));
    let stage = CorrectionStage::closed_loop(queues.clone());
    let ran = run_with(&p, Script::default(), None, stage, Some((queues.clone(), vec![a, b])));
    assert!(matches!(ran.outcome, Outcome::Completed { .. }), "{:?}", ran.outcome);
    assert_eq!(ran.allocations, 0, "the corrected tick allocated");
    assert_eq!(ran.frees, 0, "the corrected tick freed");
    assert_eq!(queues.stats.taken.load(Ordering::Relaxed), 2);
    assert_eq!(queues.stats.refused.load(Ordering::Relaxed), 0);
    let at = |k: u64| ran.sent[k as usize][1] - p.playback[(k - first) as usize].q[1];
    assert_eq!(at(first + 5), 0.0, "before the first segment: the plan");
    assert!((at(first + 35) - 0.004).abs() < 1e-12, "held");
    assert!((at(first + 50) - 0.002).abs() < 1e-12, "the second segment continues");
    assert_eq!(at(first + 100), 0.0, "after the last: the plan again");
}

/// What a capture tick asked of the camera and the trigger box, in order (atomics only: the
/// tick's allocation count stays meaningful).
#[derive(Default)]
struct CaptureLog {
    /// The tick the camera was last asked for, plus one (0: none yet).
    asked: AtomicU64,
    requests: AtomicU64,
    pulses: AtomicU64,
    /// Pulses fired before the camera had been asked for their tick.
    early_pulses: AtomicU64,
    /// The camera answers its `busy_request`-th request (1-based) busy.
    busy_request: u64,
}

struct OrderCamera(Arc<CaptureLog>);
impl ErrorType for OrderCamera {
    type Error = ErrorKind;
}
impl Lifecycle for OrderCamera {}
impl RgbdCamera for OrderCamera {
    fn configure(&mut self, c: &StreamConfig) -> Result<Intrinsics, ErrorKind> {
        Ok(c.intrinsics)
    }
    fn arm_trigger(&mut self) -> Result<(), ErrorKind> {
        Ok(())
    }
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), ErrorKind> {
        let n = self.0.requests.fetch_add(1, Ordering::Relaxed) + 1;
        if n == self.0.busy_request {
            return Err(ErrorKind::Timeout);
        }
        self.0.asked.store(request.tick + 1, Ordering::Relaxed);
        Ok(())
    }
    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, ErrorKind> {
        Ok(None)
    }
}

struct OrderTrigger(Arc<CaptureLog>);
impl ErrorType for OrderTrigger {
    type Error = ErrorKind;
}
impl Lifecycle for OrderTrigger {}
impl Trigger for OrderTrigger {
    fn fire(&mut self, tick: u64, _: TriggerLines) -> Result<(), ErrorKind> {
        self.0.pulses.fetch_add(1, Ordering::Relaxed);
        if self.0.asked.load(Ordering::Relaxed) != tick + 1 {
            self.0.early_pulses.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }
    fn poll_fired(&mut self) -> Result<Option<FireReport>, ErrorKind> {
        Ok(None)
    }
}

/// A hardware-triggered frame can reach the camera's driver within microseconds of the pulse,
/// and the driver drops a frame no request waits for: so the camera hears of each capture before
/// the box pulses its line, and a capture the camera refuses as busy is not pulsed at all.
#[test]
fn the_camera_is_asked_before_the_box_pulses_and_a_busy_capture_is_not_pulsed() {
    let _one = serial();
    let p = program();
    let captures = p.capture.iter().filter(|&&c| c).count() as u64;
    let log = Arc::new(CaptureLog { busy_request: 2, ..CaptureLog::default() });
    let (camera, trigger) = (OrderCamera(Arc::clone(&log)), OrderTrigger(Arc::clone(&log)));
    let stage = CorrectionStage::open_loop();
    let ran = run_with_lines(&p, Script::default(), None, stage, None, camera, trigger);
    assert!(matches!(ran.outcome, Outcome::Completed { .. }), "{:?}", ran.outcome);
    assert_eq!(captures, 5);
    assert_eq!(log.requests.load(Ordering::Relaxed), captures);
    assert_eq!(log.pulses.load(Ordering::Relaxed), captures - 1, "the busy capture is not pulsed");
    assert_eq!(log.early_pulses.load(Ordering::Relaxed), 0, "a pulse came before its request");
    assert_eq!(ran.allocations, 0, "the capture ticks allocated");
}

#[test]
fn operator_stop_decelerates_with_a_ruckig_stop_and_exits_130() {
    let _one = serial();
    let p = program();
    let trip_at = p.approach.len() as u64 + 120;
    let ran = run(&p, Script::default(), Some(trip_at));
    let Outcome::Tripped { trip, stopped } = ran.outcome else { panic!("{:?}", ran.outcome) };
    assert_eq!(trip.kind, TripKind::OperatorStop);
    assert!(stopped, "the controlled stop completed");
    assert_eq!(trip.kind.exit_code(), 130);
    assert_eq!(ran.allocations, 0, "the trip path allocated on the loop thread");
    assert_eq!(ran.frees, 0, "the trip path freed on the loop thread");
    // After the trip the commands stop short of the program and come to rest smoothly.
    let k = trip.tick as usize;
    let tail = &ran.sent[k..];
    assert!(tail.len() < p.approach.len() + p.playback.len() - k);
    let steps: Vec<f64> = tail.windows(2).map(|w| w[1][0] - w[0][0]).collect();
    assert!(steps.last().expect("steps").abs() < 1e-6, "at rest at the end");
    for w in steps.windows(2) {
        assert!((w[1] - w[0]).abs() <= 4.0 / RATE / RATE + 1e-9, "acceleration limited");
    }
}

#[test]
fn deviation_trips_and_stops() {
    let _one = serial();
    let p = program();
    let n = p.approach.len() + 60;
    let ran = run(&p, Script { deviate_after: Some(n), ..Default::default() }, None);
    let Outcome::Tripped { trip, stopped } = ran.outcome else { panic!("{:?}", ran.outcome) };
    assert!(matches!(trip.kind, TripKind::Deviation { joint: 3, .. }), "{:?}", trip.kind);
    assert!(stopped);
    assert_eq!(trip.kind.exit_code(), 4);
}

#[test]
fn a_lost_connection_holds_and_exits_5() {
    let _one = serial();
    let p = program();
    let n = p.approach.len() + 30;
    let ran = run(&p, Script { disconnect_after: Some(n), ..Default::default() }, None);
    let Outcome::Tripped { trip, stopped } = ran.outcome else { panic!("{:?}", ran.outcome) };
    assert_eq!(trip.kind, TripKind::ConnectionLost);
    assert!(!stopped);
    assert!(ran.stopped, "the arm was told to stop");
    assert_eq!(ran.sent.len(), n);
    assert_eq!(trip.kind.exit_code(), 5);
}

#[test]
fn an_arm_that_stops_answering_holds_and_exits_5() {
    let _one = serial();
    let p = program();
    let n = p.approach.len() + 30;
    let ran = run(&p, Script { unanswered_after: Some(n), ..Default::default() }, None);
    let Outcome::Tripped { trip, stopped } = ran.outcome else { panic!("{:?}", ran.outcome) };
    assert_eq!(trip.kind, TripKind::SetpointsUnanswered);
    assert!(!stopped, "no stop trajectory to an arm that does not answer");
    assert!(ran.stopped, "the arm was told to stop");
    assert_eq!(ran.sent.len(), n);
    assert_eq!(trip.kind.exit_code(), 5);
}

/// A stub plant that is wherever it is told to be: the test is about the client, not physics.
#[cfg(feature = "stub")]
struct Follower(Joints);

#[cfg(feature = "stub")]
impl hitl_sim_stub::plant::Plant for Follower {
    fn joints(&self) -> Joints {
        self.0
    }
    fn velocities(&self) -> Joints {
        [0.0; 7]
    }
    fn command(&mut self, q: &Joints) {
        self.0 = *q;
    }
    fn reset(&mut self, q: &Joints) {
        self.0 = *q;
    }
    fn advance(&mut self, _dt: f64) {}
    fn time(&self) -> f64 {
        0.0
    }
    fn collision(&self) -> Option<hitl_sim_stub::plant::Collision> {
        None
    }
}

/// The same playback through the real `XarmClient` (pipelined servo_j over TCP, replies read
/// and counted) and the real report reader, against the stub's protocol server: the tick still
/// allocates and frees nothing, and the stub took every setpoint.
#[cfg(feature = "stub")]
#[test]
fn the_real_client_against_the_stub_allocates_and_frees_nothing_on_the_loop_thread() {
    use hitl_drivers::xarm::XarmClient;
    use hitl_drivers::xarm::{ClientConfig, ReportConfig, ReportKind, ReportReader, ServoReplies};
    use hitl_hal::ArmReports;
    use hitl_sim_stub::{Stub, StubConfig};

    let _one = serial();
    let p = program();
    let stub = Stub::start(
        StubConfig { initial_q: START, ..StubConfig::ephemeral() },
        Box::new(Follower(START)),
    )
    .expect("stub");
    let clock = MonotonicClock::new();
    let config = ClientConfig {
        servo_replies: ServoReplies::Pipelined { max_outstanding: 63 },
        ..ClientConfig::default()
    };
    let mut arm = XarmClient::connect(stub.cmd_addr(), config).expect("connect");
    let port = |kind: ReportKind| stub.report_addr(kind).expect("report port").port();
    let mut reader = ReportReader::connect(
        stub.cmd_addr().ip(),
        ReportConfig {
            port: Some(port(ReportKind::Real)),
            codes_port: Some(port(ReportKind::Normal)),
            clock: clock.clone(),
            ..ReportConfig::default()
        },
    )
    .expect("reports");
    let (slot, reports) = LatestSlot::new();
    let done = Arc::new(AtomicBool::new(false));
    let reading = {
        let done = Arc::clone(&done);
        std::thread::spawn(move || {
            while !done.load(Ordering::Acquire) {
                match reader.next_report() {
                    Ok(state) => slot.publish(state),
                    Err(_) => break,
                }
            }
        })
    };
    arm.enable_servo().expect("enable");
    let (_planner, stop) =
        StopPlanner::start(MoveLimits::uniform(1.0, 4.0, 60.0), 1.0 / RATE, 5.0).expect("planner");
    let thresholds = Thresholds {
        report_timeout_ns: 1_000_000_000,
        max_deviation_rad: 0.15,
        trip_on_warning: true,
        reply_stall_ns: 1_000_000_000,
    };
    let status = Arc::new(LoopStatus::default());
    let io =
        LoopIo { reports, telemetry: NoTelemetry, status, health: Health::default(), stop, clock };
    let devices = Devices {
        arm: &mut arm,
        camera: NoCamera,
        light: NoLight,
        inputs: NoInputs,
        trigger: NoTrigger,
    };
    let control = ControlLoop::new(&p, devices, io, Interlocks::new(thresholds), RATE, &START);
    let before = (RT_ALLOCATIONS.load(Ordering::Relaxed), RT_FREES.load(Ordering::Relaxed));
    let outcome = control.run(Duration::ZERO);
    let allocations = RT_ALLOCATIONS.load(Ordering::Relaxed) - before.0;
    let frees = RT_FREES.load(Ordering::Relaxed) - before.1;
    arm.flush_servo_replies().expect("every reply arrives");
    done.store(true, Ordering::Release);
    let _ = reading.join();
    assert!(matches!(outcome, Outcome::Completed { settled: true, .. }), "{outcome:?}");
    assert_eq!(allocations, 0, "the tick allocated with the real client");
    assert_eq!(frees, 0, "the tick freed with the real client");
    assert!(
        arm.servo_sent() >= (p.approach.len() + p.playback.len()) as u64,
        "{}",
        arm.servo_sent()
    );
    assert_eq!(arm.outstanding(), 0);
    stub.shutdown();
}
