//! The simulated RGB-D camera on the flange: triggered by the tick, rendered on a thread of its
//! own by ray casting through MuJoCo ([`render`]), delivered as [`RgbdFrame`]s through the HAL's
//! [`RgbdCamera`] trait.
//!
//! At each trigger the render thread takes the exposure: it samples the plant's measured joints
//! ([`SharedArmState`]) and the light level ([`LightLevel`]) as the request arrives, then renders
//! with its own `MjData`. Next to each frame it keeps a [`RenderTruth`] (the joints it rendered
//! at, the camera pose with and without noise) for ground truth: [`SimCamera::poll_sim_frame`]
//! returns both, [`SimCamera::last_truth`] gives the truth of the frame `poll_frame` returned last.
//!
//! Clocks: `exposure_ns` is the host monotonic clock given in [`SimCameraConfig::clock`] (share
//! the controller's); `device_ns` is the plant's simulated time at the exposure, in nanoseconds.

pub mod bench;
pub mod intrinsics;
pub mod noise;
pub mod render;

pub use bench::bench_render;
pub use intrinsics::Preset;
pub use noise::{FrameNoise, NoiseModel};
pub use render::{Image, Renderer, Shading};

use crate::mujoco_plant::{LabModel, SharedArmState};
use crossbeam::atomic::AtomicCell;
use crossbeam::channel::{self, Receiver, Sender, TryRecvError, TrySendError};
use hitl_hal::{
    CaptureRequest, Clock, ErrorKind, ErrorType, Intrinsics, Joints, MonotonicClock, RgbdCamera,
    RgbdFrame, StreamConfig, TimestampSource,
};
use nalgebra::Isometry3;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

/// The light level the simulated Sun shines at (0 off .. 1 full), shared lock-free with whatever
/// plays the light (the simulated light driver, a test).
#[derive(Debug, Clone)]
pub struct LightLevel(Arc<AtomicCell<f32>>);

impl LightLevel {
    pub fn new(level: f32) -> Self {
        Self(Arc::new(AtomicCell::new(level)))
    }
    pub fn set(&self, level: f32) {
        self.0.store(if level.is_finite() { level.clamp(0.0, 1.0) } else { 0.0 })
    }
    pub fn get(&self) -> f32 {
        self.0.load()
    }
}

impl Default for LightLevel {
    fn default() -> Self {
        Self::new(1.0)
    }
}

/// What a rendered frame really shows: for ground truth and for checking the noise.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderTruth {
    /// The capture this truth belongs to.
    pub tick: u64,
    /// The measured joints the frame was rendered at.
    pub q: Joints,
    /// The plant's simulated time at the exposure, seconds.
    pub sim_time_s: f64,
    /// Light level at the exposure.
    pub light_level: f32,
    /// The camera pose (OpenCV axes) in the arm-base frame from the model's kinematics at `q`.
    pub camera_in_base: Isometry3<f64>,
    /// The pose actually rendered from (the nominal pose turned by the sigma_theta noise).
    pub rendered_camera_in_base: Isometry3<f64>,
    /// The principal point shift of the sigma_px noise, pixels.
    pub shift_px: [f64; 2],
}

/// How the simulated camera runs.
#[derive(Debug, Clone)]
pub struct SimCameraConfig {
    pub intrinsics: Intrinsics,
    pub noise: NoiseModel,
    pub shading: Shading,
    /// Host clock for `exposure_ns` (share the controller's so stamps compare).
    pub clock: MonotonicClock,
    /// Captures that may wait for the render thread; a trigger beyond this is refused.
    pub queue: usize,
}

impl Default for SimCameraConfig {
    fn default() -> Self {
        Self {
            intrinsics: Preset::Orbbec.at(640, 400),
            noise: NoiseModel::default(),
            shading: Shading::default(),
            clock: MonotonicClock::new(),
            queue: 4,
        }
    }
}

/// What went wrong with the simulated camera.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimCameraError {
    #[error("simulated camera: {0}")]
    Config(String),
    #[error("simulated camera: capture queue full, trigger for tick {0} dropped")]
    Busy(u64),
    #[error("simulated camera: trigger before arm_trigger")]
    NotArmed,
    #[error("simulated camera: render thread is gone")]
    Disconnected,
}

impl hitl_hal::Error for SimCameraError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Config(_) | Self::NotArmed => ErrorKind::InvalidRequest,
            Self::Busy(_) => ErrorKind::Timeout,
            Self::Disconnected => ErrorKind::Disconnected,
        }
    }
}

/// The simulated RGB-D camera.
pub struct SimCamera {
    requests: Option<Sender<CaptureRequest>>,
    /// The intrinsics the render thread uses for its next capture.
    stream: Arc<AtomicCell<Intrinsics>>,
    frames: Receiver<(RgbdFrame, RenderTruth)>,
    thread: Option<JoinHandle<()>>,
    intrinsics: Intrinsics,
    mask: bool,
    armed: bool,
    last_truth: Option<RenderTruth>,
    dropped: Arc<AtomicU64>,
}

impl std::fmt::Debug for SimCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimCamera").field("intrinsics", &self.intrinsics).finish()
    }
}

impl SimCamera {
    /// A camera rendering `lab` (share the plant's: `plant.lab_model()`) at the joints the plant
    /// publishes (`plant.shared_state()`), lit at `light`'s level. Starts its render thread.
    pub fn new(
        lab: LabModel,
        arm: SharedArmState,
        light: LightLevel,
        config: SimCameraConfig,
    ) -> Result<Self, SimCameraError> {
        if let Some(e) = intrinsics::check(&config.intrinsics).or_else(|| config.noise.check()) {
            return Err(SimCameraError::Config(e));
        }
        let mut renderer = Renderer::new(lab).map_err(SimCameraError::Config)?;
        renderer.shading = config.shading;
        let (req_tx, req_rx) = channel::bounded(config.queue.max(1));
        let stream = Arc::new(AtomicCell::new(config.intrinsics));
        let (frame_tx, frame_rx) = channel::bounded(config.queue.max(1) + 2);
        let dropped = Arc::new(AtomicU64::new(0));
        let worker = Worker {
            renderer,
            arm,
            light,
            noise: config.noise,
            clock: config.clock,
            stream: stream.clone(),
            frames: frame_tx,
            dropped: dropped.clone(),
        };
        let thread = std::thread::Builder::new()
            .name("sim-camera".into())
            .spawn(move || worker.run(req_rx))
            .map_err(|e| SimCameraError::Config(format!("cannot start render thread: {e}")))?;
        Ok(Self {
            requests: Some(req_tx),
            stream,
            frames: frame_rx,
            thread: Some(thread),
            intrinsics: config.intrinsics,
            mask: true,
            armed: false,
            last_truth: None,
            dropped,
        })
    }

    /// Take a delivered frame with its truth, if one is ready (never blocks).
    pub fn poll_sim_frame(&mut self) -> Result<Option<(RgbdFrame, RenderTruth)>, SimCameraError> {
        match self.frames.try_recv() {
            Ok((mut frame, truth)) => {
                if !self.mask {
                    frame.mask = None;
                }
                Ok(Some((frame, truth)))
            }
            Err(TryRecvError::Empty) => Ok(None),
            Err(TryRecvError::Disconnected) => Err(SimCameraError::Disconnected),
        }
    }

    /// The truth of the frame [`RgbdCamera::poll_frame`] returned last.
    pub fn last_truth(&self) -> Option<&RenderTruth> {
        self.last_truth.as_ref()
    }

    /// Frames rendered but dropped because nobody polled them in time.
    pub fn dropped_frames(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

impl Drop for SimCamera {
    fn drop(&mut self) {
        self.requests = None; // the render thread ends when its request channel closes
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl ErrorType for SimCamera {
    type Error = SimCameraError;
}

impl RgbdCamera for SimCamera {
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, SimCameraError> {
        if let Some(e) = intrinsics::check(&config.intrinsics) {
            return Err(SimCameraError::Config(e));
        }
        // The render thread uses it from the next capture it takes.
        self.stream.store(config.intrinsics);
        self.intrinsics = config.intrinsics;
        self.mask = config.mask;
        Ok(self.intrinsics)
    }

    fn arm_trigger(&mut self) -> Result<(), SimCameraError> {
        self.armed = true;
        Ok(())
    }

    /// Hands the request to the render thread's bounded queue (`try_send`: no allocation, no
    /// blocking). A full queue refuses the capture with [`SimCameraError::Busy`].
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), SimCameraError> {
        if !self.armed {
            return Err(SimCameraError::NotArmed);
        }
        let tx = self.requests.as_ref().ok_or(SimCameraError::Disconnected)?;
        match tx.try_send(request) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => Err(SimCameraError::Busy(request.tick)),
            Err(TrySendError::Disconnected(_)) => Err(SimCameraError::Disconnected),
        }
    }

    fn poll_frame(&mut self) -> Result<Option<RgbdFrame>, SimCameraError> {
        Ok(self.poll_sim_frame()?.map(|(frame, truth)| {
            self.last_truth = Some(truth);
            frame
        }))
    }
}

/// The render thread's state.
struct Worker {
    renderer: Renderer,
    arm: SharedArmState,
    light: LightLevel,
    noise: NoiseModel,
    clock: MonotonicClock,
    stream: Arc<AtomicCell<Intrinsics>>,
    frames: Sender<(RgbdFrame, RenderTruth)>,
    dropped: Arc<AtomicU64>,
}

impl Worker {
    fn run(mut self, requests: Receiver<CaptureRequest>) {
        while let Ok(request) = requests.recv() {
            let out = self.capture(request);
            if self.frames.try_send(out).is_err() {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    fn capture(&mut self, request: CaptureRequest) -> (RgbdFrame, RenderTruth) {
        // The exposure: what the arm and the light are doing as the trigger arrives.
        let sample = self.arm.load();
        let exposure_ns = self.clock.now_ns();
        let level = self.light.get();
        let mut noise = self.noise.draw(request.tick);
        let (image, truth) =
            render_capture(&mut self.renderer, &sample.q, &self.stream.load(), level, &mut noise);
        let frame = RgbdFrame {
            request,
            device_ns: (sample.sim_time_s.max(0.0) * 1e9) as u64,
            exposure_ns,
            timestamp: TimestampSource::DeviceExposure,
            intrinsics: image.intrinsics,
            color: image.color,
            depth_m: image.depth_m,
            mask: Some(image.mask),
        };
        let truth = RenderTruth {
            tick: request.tick,
            sim_time_s: sample.sim_time_s,
            light_level: level,
            ..truth
        };
        (frame, truth)
    }
}

/// Render one capture at joints `q` with the frame's noise; the truth's tick and time are left
/// for the caller to fill.
pub fn render_capture(
    renderer: &mut Renderer,
    q: &Joints,
    intr: &Intrinsics,
    level: f32,
    noise: &mut FrameNoise,
) -> (Image, RenderTruth) {
    renderer.set_joints(q);
    let camera = renderer.camera_in_lab();
    let rendered = camera * noise.rotation;
    let mut image = renderer.render_from(&rendered, intr, level, noise.shift_px);
    noise.apply_depth(&mut image.depth_m);
    let base_inv = renderer.base_in_lab().inverse();
    let truth = RenderTruth {
        tick: 0,
        q: *q,
        sim_time_s: 0.0,
        light_level: level,
        camera_in_base: base_inv * camera,
        rendered_camera_in_base: base_inv * rendered,
        shift_px: noise.shift_px,
    };
    (image, truth)
}
