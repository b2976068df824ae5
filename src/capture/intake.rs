//! The capture intake thread: every frame the camera delivers is matched to its capture (the tick
//! that fired it), to the arm's joints at exposure (interpolated from the report stream) and to
//! ground truth; then recorded (images, calibration, `/tf`, `/pose/gt`) and handed to perception.
//! It also measures the sync error: exposure time minus the tick's trigger time.

use super::history::StateHistory;
use super::mask::{MaskDrawer, MaskSource, MaskStats};
use super::sink::IntakeQueues;
use super::truth::LabFrames;
use crate::telemetry::CaptureOut;
use hitl_hal::RgbdFrame;
use hitl_perception::{PerceptionFrame, WorkerHandle};
use hitl_record::{CaptureSyncMsg, EventKind, FrameRecord, SafetyEventMsg, Telemetry};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// What the intake saw over a run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct IntakeStats {
    /// Frames that arrived.
    pub frames: u64,
    /// Frames recorded (handed to the recorder's frame queue).
    pub recorded: u64,
    /// Frames that could not be recorded or were lost before the intake (each is an event).
    pub not_recorded: u64,
    /// Captures the camera was too busy to take (each is a `capture-not-recorded` event).
    pub captures_missed: u64,
    /// Frames handed to perception.
    pub to_perception: u64,
    /// Exposure minus trigger, nanoseconds: mean and largest magnitude.
    pub sync_error_mean_ns: f64,
    pub sync_error_max_ns: u64,
    /// Where the masks came from, and (`rendered`) how drawing them went.
    pub mask: MaskStats,
}

/// Where frames go after the intake.
pub struct IntakeOutputs {
    pub record: Option<Telemetry>,
    pub perception: Option<WorkerHandle>,
}

/// The mask every frame gets on its way to the recorder and perception.
pub enum IntakeMask {
    /// The camera's own (the simulated camera's), as delivered.
    Camera,
    /// Drawn from the controller's lab at the exposure (the camera's own, if any, is only
    /// compared with).
    Rendered(Box<MaskDrawer>),
    /// None, whatever the camera delivered.
    Dropped,
}

impl IntakeMask {
    fn source(&self) -> MaskSource {
        match self {
            Self::Camera => MaskSource::Sim,
            Self::Rendered(_) => MaskSource::Rendered,
            Self::Dropped => MaskSource::None,
        }
    }
}

/// The running intake; `finish` drains what is left and returns the statistics.
pub struct Intake {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<IntakeStats>>,
}

impl Intake {
    pub fn spawn(
        queues: Arc<IntakeQueues>,
        frames: LabFrames,
        out: IntakeOutputs,
        mask: IntakeMask,
    ) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let stop_flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("hitl-capture-intake".into())
            .spawn(move || Worker::new(queues, frames, out, mask).run(&stop_flag))?;
        Ok(Self { stop, thread: Some(thread) })
    }

    /// Process what is still queued, stop, and report.
    pub fn finish(mut self) -> IntakeStats {
        self.stop.store(true, Ordering::Release);
        self.thread.take().and_then(|t| t.join().ok()).unwrap_or_default()
    }
}

impl Drop for Intake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Worker {
    queues: Arc<IntakeQueues>,
    frames: LabFrames,
    out: IntakeOutputs,
    mask: IntakeMask,
    history: StateHistory,
    captures: VecDeque<CaptureOut>,
    stats: IntakeStats,
    sync_sum_ns: f64,
    lost_seen: u64,
}

impl Worker {
    fn new(
        queues: Arc<IntakeQueues>,
        frames: LabFrames,
        out: IntakeOutputs,
        mask: IntakeMask,
    ) -> Self {
        let stats = IntakeStats {
            mask: MaskStats { source: Some(mask.source()), ..MaskStats::default() },
            ..IntakeStats::default()
        };
        Self {
            queues,
            frames,
            out,
            mask,
            history: StateHistory::new(4096),
            captures: VecDeque::new(),
            stats,
            sync_sum_ns: 0.0,
            lost_seen: 0,
        }
    }

    fn run(mut self, stop: &AtomicBool) -> IntakeStats {
        loop {
            let stopping = stop.load(Ordering::Acquire);
            let worked = self.drain();
            if stopping && !worked {
                break;
            }
            if !worked {
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        self.stats.captures_missed = self.queues.captures_missed.load(Ordering::Relaxed);
        if let IntakeMask::Rendered(d) = &self.mask {
            self.stats.mask = d.stats().clone();
        }
        self.stats
    }

    /// One pass over the queues; whether anything was there.
    fn drain(&mut self) -> bool {
        let mut worked = self.take_states();
        while let Some(capture) = self.queues.captures.pop() {
            if self.captures.len() == 1024 {
                self.captures.pop_front();
            }
            self.captures.push_back(capture);
            worked = true;
        }
        let lost = self.queues.frames_lost.load(Ordering::Relaxed);
        for _ in self.lost_seen..lost {
            self.not_recorded(0, 0, "a frame arrived while the capture intake was full");
        }
        self.lost_seen = lost;
        while let Some(frame) = self.queues.frames.pop() {
            // The capture record follows the frame's tick; give a late one a moment.
            self.take_states();
            self.handle(frame);
            self.queues.frames_done.fetch_add(1, Ordering::AcqRel);
            worked = true;
        }
        // Frames the tick could not queue: freed here, off the loop thread.
        while let Some(lost) = self.queues.discard.pop() {
            drop(lost);
            worked = true;
        }
        worked
    }

    /// Moves the arm states the tick queued into the history; whether there were any. Called
    /// between frames and while a frame waits for the recorder: the queue holds 16 s of states
    /// at 250 Hz, and an intake held up longer by a slow recorder would otherwise lose the
    /// states around the exposures still waiting, and match those frames to the wrong pose.
    fn take_states(&mut self) -> bool {
        let mut any = false;
        while let Some(state) = self.queues.states.pop() {
            self.history.push(state);
            any = true;
        }
        any
    }

    fn not_recorded(&mut self, t_ns: u64, tick: u64, why: &str) {
        self.stats.not_recorded += 1;
        if let Some(r) = &self.out.record {
            r.push_event(SafetyEventMsg::text(
                t_ns,
                EventKind::CaptureNotRecorded,
                format!("capture at tick {tick} not recorded: {why}"),
            ));
        }
    }

    fn handle(&mut self, mut frame: RgbdFrame) {
        self.stats.frames += 1;
        let request = frame.request;
        let capture = self.captures.iter().find(|c| c.tick == request.tick).copied();
        let sync_ns = CaptureSyncMsg::error_ns(request.fired_ns, frame.exposure_ns);
        self.sync_sum_ns += sync_ns as f64;
        self.stats.sync_error_max_ns = self.stats.sync_error_max_ns.max(sync_ns.unsigned_abs());
        self.stats.sync_error_mean_ns = self.sync_sum_ns / self.stats.frames as f64;

        let q = self
            .history
            .joints_at(frame.exposure_ns)
            .or(capture.map(|c| c.commanded.q))
            .unwrap_or([0.0; hitl_hal::DOF]);
        let gt = self.frames.target_in_camera(&q);
        // The frame's mask as the run chose: the camera's, drawn at this pose, or none. An empty
        // drawn mask (target out of view) goes on as it is: the estimator finds no target and
        // the frame is scored as failed.
        match &mut self.mask {
            IntakeMask::Camera => {}
            IntakeMask::Rendered(drawer) => {
                let truth = frame.mask.take();
                frame.mask = Some(Arc::new(drawer.draw(
                    &gt,
                    &frame.intrinsics,
                    truth.as_deref().map(Vec::as_slice),
                )));
            }
            IntakeMask::Dropped => frame.mask = None,
        }

        if let Some(worker) = &self.out.perception {
            worker.push(PerceptionFrame {
                timestamp_ns: frame.exposure_ns,
                seq: request.tick,
                intrinsics: frame.intrinsics,
                // The recorder's pixels, shared: no copy.
                color: Arc::clone(&frame.color),
                depth_m: Arc::clone(&frame.depth_m),
                mask: frame.mask.clone(),
            });
            self.stats.to_perception += 1;
        }
        if let Some(record) = &self.out.record {
            let mut rec = FrameRecord::from_rgbd(frame);
            rec.gt_pose = Some(gt);
            rec.tf = Some(self.frames.tf(rec.capture_ns, &q));
            // The level the light was at for this exposure (the tick's, sent a lead earlier).
            rec.light_level = capture.map(|c| c.light_level).filter(|l| l.is_finite());
            let deadline = std::time::Instant::now() + Duration::from_secs(2);
            while !record.frame_queue_has_room() && std::time::Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(5));
                while let Some(state) = self.queues.states.pop() {
                    self.history.push(state);
                }
            }
            if record.push_frame(rec) {
                self.stats.recorded += 1;
            } else {
                self.stats.not_recorded += 1;
            }
        }
    }
}
