//! The simulated RGB-D camera on the flange: triggered by the tick, rendered on a thread of its
//! own, delivered as [`RgbdFrame`]s through the HAL's [`RgbdCamera`] trait.
//!
//! Two renderers ([`RendererKind`]): MuJoCo's own OpenGL renderer ([`gl`], the default: lit by
//! the scene's lights with its materials, about 11x the ray cast's frames/s at 1280x1024 on a
//! 2-core machine with Mesa's software EGL device), and the ray cast ([`render`]: one
//! `mj_multiRay` per pixel, flat Lambert shading). The ray cast stays for the renderer benchmark
//! (`hitl bench render` puts the two side by side) and as the independent geometry the
//! renderer's depth and mask are tested against; runs use MuJoCo's renderer. Without a usable
//! EGL device [`SimCamera::new`] fails with [`SimCameraError::NoRenderer`] naming the missing
//! Debian package, before anything moves.
//!
//! The exposure happens at the trigger, as a hardware-triggered camera's does: `trigger` (called
//! by the tick) samples the plant's measured joints ([`SharedArmState`], a lock-free load), the
//! light level ([`LightLevel`]) and the clock, and queues them with the request; the render
//! thread then renders that exposure with its own `MjData`, however late it gets to it (the
//! readout), and hands the image to a readout thread that applies the depth model
//! ([`NoiseModel`]: the Orbbec model passes over every pixel) and delivers the frame, so the next
//! capture renders while the last one is read out (issue 23: 10 Hz at 1280x800). A render
//! backlog therefore delays delivery, never moves the exposure away from its trigger; the queue
//! of exposures is deep ([`EXPOSURE_QUEUE`]), and only a full one refuses the capture (`Busy`).
//! Next to each frame it keeps a [`RenderTruth`] (the joints it rendered at, the camera pose with
//! and without noise) for ground truth: [`SimCamera::poll_sim_frame`] returns both,
//! [`SimCamera::last_truth`] gives the truth of the frame `poll_frame` returned last.
//!
//! Clocks: `exposure_ns` is the host monotonic clock given in [`SimCameraConfig::clock`] (share
//! the controller's); `device_ns` is the plant's simulated time at the exposure, in nanoseconds.

pub mod bench;
pub mod gl;
pub mod intrinsics;
pub mod lens;
pub mod noise;
pub mod render;

pub use bench::bench_render;
pub use gl::GlRenderer;
pub use intrinsics::Preset;
pub use lens::{LensCache, LensMap};
pub use noise::{DepthModel, FrameNoise, NoiseModel, StereoDepth};
pub use render::{Image, Renderer, Shading};

use crate::mujoco_plant::{ArmSample, LabModel, SharedArmState};
use crossbeam::atomic::AtomicCell;
use crossbeam::channel::{self, Receiver, Sender, TryRecvError, TrySendError};
use hitl_hal::{
    CaptureRequest, Clock, Distortion, ErrorKind, ErrorType, Intrinsics, Joints, MonotonicClock,
    Pose, RgbdCamera, RgbdFrame, StreamConfig, TimestampSource,
};
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
    pub camera_in_base: Pose,
    /// The pose actually rendered from (the nominal pose turned by the sigma_theta noise).
    pub rendered_camera_in_base: Pose,
    /// The principal point shift of the sigma_px noise, pixels.
    pub shift_px: [f64; 2],
}

/// Which renderer draws the simulated camera's frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RendererKind {
    /// MuJoCo's OpenGL renderer on an offscreen EGL context ([`gl`]).
    #[default]
    Mujoco,
    /// One ray per pixel through `mj_multiRay` ([`render`]): for the benchmark and tests.
    RayCast,
}

/// How the simulated camera runs.
#[derive(Debug, Clone)]
pub struct SimCameraConfig {
    /// The stream asked for; its distortion is replaced by [`Self::lens`].
    pub intrinsics: Intrinsics,
    /// The simulated lens (the lab's `[camera] distortion`): every frame is rendered through
    /// it and the camera announces it in its intrinsics, as a real camera's factory calibration
    /// (docs/sim-camera.md). [`Distortion::NONE`]: a pinhole.
    pub lens: Distortion,
    pub renderer: RendererKind,
    pub noise: NoiseModel,
    pub shading: Shading,
    /// Host clock for `exposure_ns` (share the controller's so stamps compare).
    pub clock: MonotonicClock,
    /// Captures that may wait for the render thread; a trigger beyond this is refused. Each is
    /// the exposure's few numbers (no image yet), so the default, [`EXPOSURE_QUEUE`], is deep.
    pub queue: usize,
    /// Counts captures taken and rendered (a host on a simulated clock waits until they match).
    pub backlog: RenderBacklog,
}

/// The default depth of the exposure queue: 6.4 s of captures at 10 Hz. A real camera exposes
/// at every trigger and delivers every frame, whatever the host is doing; the simulated one
/// exposes at the trigger too (the joints, the light and the clock are sampled there) but renders
/// on this machine's cores, which other work (perception, the recorder, other processes) may hold
/// for a while. Behind a deep queue a slow render delays frames instead of losing captures; the
/// session collects the backlog after the loop (issue 23: no capture lost at 10 Hz).
pub const EXPOSURE_QUEUE: usize = 64;

/// Captures the camera has taken and the ones its render thread has finished (delivered or
/// dropped); cheap to clone, readable from any thread.
#[derive(Debug, Clone, Default)]
pub struct RenderBacklog(Arc<(AtomicU64, AtomicU64)>);

impl RenderBacklog {
    /// Whether every capture taken so far has been rendered.
    pub fn idle(&self) -> bool {
        self.0 .1.load(Ordering::Acquire) >= self.0 .0.load(Ordering::Acquire)
    }

    /// Captures the render thread has finished (delivered or dropped).
    pub fn rendered(&self) -> u64 {
        self.0 .1.load(Ordering::Acquire)
    }

    fn taken(&self) {
        self.0 .0.fetch_add(1, Ordering::AcqRel);
    }

    fn finished(&self) {
        self.0 .1.fetch_add(1, Ordering::AcqRel);
    }
}

impl Default for SimCameraConfig {
    fn default() -> Self {
        Self {
            intrinsics: Preset::Orbbec.at(640, 400),
            lens: Distortion::NONE,
            renderer: RendererKind::default(),
            noise: NoiseModel::default(),
            shading: Shading::default(),
            clock: MonotonicClock::new(),
            queue: EXPOSURE_QUEUE,
            backlog: RenderBacklog::default(),
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
    /// The renderer could not start (no usable EGL device, a scene it cannot draw).
    #[error("simulated camera: {0}")]
    NoRenderer(String),
}

impl hitl_hal::Error for SimCameraError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Config(_) | Self::NotArmed => ErrorKind::InvalidRequest,
            Self::Busy(_) => ErrorKind::Timeout,
            Self::Disconnected => ErrorKind::Disconnected,
            Self::NoRenderer(_) => ErrorKind::NotFound,
        }
    }
}

/// One capture as exposed at its trigger, waiting for the render thread.
#[derive(Debug, Clone, Copy)]
struct Exposure {
    request: CaptureRequest,
    /// The arm as measured at the trigger.
    sample: ArmSample,
    /// Host clock at the trigger.
    exposure_ns: u64,
    /// Light level at the trigger.
    level: f32,
}

/// The simulated RGB-D camera.
pub struct SimCamera {
    requests: Option<Sender<Exposure>>,
    arm: SharedArmState,
    light: LightLevel,
    clock: MonotonicClock,
    /// The intrinsics the render thread uses for its next capture.
    stream: Arc<AtomicCell<Intrinsics>>,
    frames: Receiver<(RgbdFrame, RenderTruth)>,
    thread: Option<JoinHandle<()>>,
    readout: Option<JoinHandle<()>>,
    intrinsics: Intrinsics,
    lens: Distortion,
    mask: bool,
    armed: bool,
    last_truth: Option<RenderTruth>,
    dropped: Arc<AtomicU64>,
    backlog: RenderBacklog,
}

impl std::fmt::Debug for SimCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimCamera").field("intrinsics", &self.intrinsics).finish()
    }
}

impl SimCamera {
    /// A camera rendering `lab` (share the plant's: `plant.lab_model()`) at the joints the plant
    /// publishes (`plant.shared_state()`), lit at `light`'s level. Starts its render thread and
    /// waits for its renderer to open (MuJoCo's: its EGL context lives on that thread).
    pub fn new(
        lab: LabModel,
        arm: SharedArmState,
        light: LightLevel,
        config: SimCameraConfig,
    ) -> Result<Self, SimCameraError> {
        let k = config.intrinsics.with_distortion(config.lens);
        let refused = intrinsics::check(&k)
            .or_else(|| lens::check(&k, &config.lens))
            .or_else(|| config.noise.check());
        if let Some(e) = refused {
            return Err(SimCameraError::Config(e));
        }
        let (req_tx, req_rx) = channel::bounded(config.queue.max(1));
        let stream = Arc::new(AtomicCell::new(k));
        // Rendered frames waiting for a poll (the tick polls every period): at most 8, 64 MB
        // at 1280x800, however deep the exposure queue.
        let (frame_tx, frame_rx) = channel::bounded(config.queue.clamp(1, 6) + 2);
        // One rendered image waits for the readout while the next renders.
        let (image_tx, image_rx) = channel::bounded::<Rendered>(1);
        let dropped = Arc::new(AtomicU64::new(0));
        let (ready_tx, ready_rx) = channel::bounded(1);
        let kind = config.renderer;
        let shading = config.shading;
        let size = (config.intrinsics.width, config.intrinsics.height);
        let readout =
            Readout { frames: frame_tx, dropped: dropped.clone(), backlog: config.backlog.clone() };
        let readout = std::thread::Builder::new()
            .name("sim-camera-readout".into())
            .spawn(move || readout.run(image_rx))
            .map_err(|e| SimCameraError::Config(format!("cannot start readout thread: {e}")))?;
        let worker_stream = stream.clone();
        let backlog = config.backlog.clone();
        let worker = move |renderer| Worker {
            renderer,
            noise: config.noise,
            stream: worker_stream,
            lens: LensCache::default(),
            images: image_tx,
            backlog,
        };
        let thread = std::thread::Builder::new()
            .name("sim-camera".into())
            .spawn(move || {
                let renderer = match Backend::open(kind, lab, shading, size) {
                    Ok(r) => r,
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let _ = ready_tx.send(Ok(()));
                worker(renderer).run(req_rx)
            })
            .map_err(|e| SimCameraError::Config(format!("cannot start render thread: {e}")))?;
        let opened = ready_rx.recv().unwrap_or(Err(SimCameraError::Disconnected));
        if let Err(e) = opened {
            let _ = thread.join();
            let _ = readout.join();
            return Err(e);
        }
        Ok(Self {
            requests: Some(req_tx),
            arm,
            light,
            clock: config.clock,
            stream,
            frames: frame_rx,
            thread: Some(thread),
            readout: Some(readout),
            intrinsics: k,
            lens: config.lens,
            mask: true,
            armed: false,
            last_truth: None,
            dropped,
            backlog: config.backlog,
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
        // The render thread ends when its request channel closes, the readout thread when the
        // render thread's image channel does.
        self.requests = None;
        for t in [self.thread.take(), self.readout.take()].into_iter().flatten() {
            let _ = t.join();
        }
    }
}

impl ErrorType for SimCamera {
    type Error = SimCameraError;
}

impl RgbdCamera for SimCamera {
    /// Returns the stream asked for with the camera's own lens: the distortion it renders
    /// through, whatever the request said (a real camera's factory calibration is not asked).
    fn configure(&mut self, config: &StreamConfig) -> Result<Intrinsics, SimCameraError> {
        let k = config.intrinsics.with_distortion(self.lens);
        if let Some(e) = intrinsics::check(&k).or_else(|| lens::check(&k, &self.lens)) {
            return Err(SimCameraError::Config(e));
        }
        // The render thread uses it from the next capture it takes.
        self.stream.store(k);
        self.intrinsics = k;
        self.mask = config.mask;
        Ok(self.intrinsics)
    }

    fn arm_trigger(&mut self) -> Result<(), SimCameraError> {
        self.armed = true;
        Ok(())
    }

    /// Exposes now (samples the arm, the light and the clock) and hands the exposure to the
    /// render thread's bounded queue (`try_send`: no allocation, no blocking). A full queue
    /// refuses the capture with [`SimCameraError::Busy`].
    fn trigger(&mut self, request: CaptureRequest) -> Result<(), SimCameraError> {
        if !self.armed {
            return Err(SimCameraError::NotArmed);
        }
        let tx = self.requests.as_ref().ok_or(SimCameraError::Disconnected)?;
        let exposure = Exposure {
            request,
            sample: self.arm.load(),
            exposure_ns: self.clock.now_ns(),
            level: self.light.get(),
        };
        match tx.try_send(exposure) {
            Ok(()) => {
                self.backlog.taken();
                Ok(())
            }
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

/// The renderer a camera's thread draws with.
pub enum Backend {
    RayCast(Box<Renderer>),
    Mujoco(Box<GlRenderer>),
}

impl Backend {
    /// Open `kind` on the calling thread (MuJoCo's renderer at `size` first).
    pub fn open(
        kind: RendererKind,
        lab: LabModel,
        shading: Shading,
        size: (u32, u32),
    ) -> Result<Self, SimCameraError> {
        Ok(match kind {
            RendererKind::RayCast => {
                let mut r = Renderer::new(lab).map_err(SimCameraError::Config)?;
                r.shading = shading;
                Backend::RayCast(Box::new(r))
            }
            RendererKind::Mujoco => {
                let mut r = GlRenderer::new(lab, size.0, size.1)
                    .map_err(|e| SimCameraError::NoRenderer(e.to_string()))?;
                r.shading = shading;
                Backend::Mujoco(Box::new(r))
            }
        })
    }
}

/// What a renderer does for one capture (both renderers have it).
pub trait Draw {
    type Error;
    /// Put the arm at `q` and compute the kinematics.
    fn set_joints(&mut self, q: &Joints);
    /// Camera pose (OpenCV axes) in the lab frame for the current joints.
    fn camera_in_lab(&self) -> Pose;
    /// The arm base's pose in the lab frame.
    fn base_in_lab(&self) -> Pose;
    /// Render from `camera` (OpenCV axes, lab frame), principal point moved by `shift_px`.
    fn render_from(
        &mut self,
        camera: &Pose,
        intr: &Intrinsics,
        level: f32,
        shift_px: [f64; 2],
    ) -> Result<Image, Self::Error>;
}

impl Draw for Renderer {
    type Error = std::convert::Infallible;
    fn set_joints(&mut self, q: &Joints) {
        Renderer::set_joints(self, q)
    }
    fn camera_in_lab(&self) -> Pose {
        Renderer::camera_in_lab(self)
    }
    fn base_in_lab(&self) -> Pose {
        Renderer::base_in_lab(self)
    }
    fn render_from(
        &mut self,
        camera: &Pose,
        intr: &Intrinsics,
        level: f32,
        shift_px: [f64; 2],
    ) -> Result<Image, Self::Error> {
        Ok(Renderer::render_from(self, camera, intr, level, shift_px))
    }
}

impl Draw for GlRenderer {
    type Error = gl::GlError;
    fn set_joints(&mut self, q: &Joints) {
        GlRenderer::set_joints(self, q)
    }
    fn camera_in_lab(&self) -> Pose {
        GlRenderer::camera_in_lab(self)
    }
    fn base_in_lab(&self) -> Pose {
        GlRenderer::base_in_lab(self)
    }
    fn render_from(
        &mut self,
        camera: &Pose,
        intr: &Intrinsics,
        level: f32,
        shift_px: [f64; 2],
    ) -> Result<Image, Self::Error> {
        GlRenderer::render_from(self, camera, intr, level, shift_px)
    }
}

/// The render thread's state.
struct Worker {
    renderer: Backend,
    noise: NoiseModel,
    stream: Arc<AtomicCell<Intrinsics>>,
    /// The remap of the stream's lens, built once.
    lens: LensCache,
    images: Sender<Rendered>,
    backlog: RenderBacklog,
}

/// A capture rendered (through the lens), its depth model still to apply.
struct Rendered {
    exposure: Exposure,
    image: Image,
    truth: RenderTruth,
    noise: FrameNoise,
}

impl Worker {
    fn run(mut self, exposures: Receiver<Exposure>) {
        while let Ok(exposure) = exposures.recv() {
            // A renderer that fails after it opened ends the thread (and so the readout's): the
            // camera then reports itself disconnected at the next poll, which faults the run.
            let Ok(rendered) = self.render(exposure) else {
                self.backlog.finished();
                return;
            };
            if self.images.send(rendered).is_err() {
                self.backlog.finished();
                return;
            }
        }
    }

    fn render(&mut self, exposure: Exposure) -> Result<Rendered, String> {
        let tick = exposure.request.tick;
        let noise = self.noise.draw(tick);
        let intr = self.stream.load();
        let (image, truth) = match &mut self.renderer {
            Backend::RayCast(r) => {
                let Ok(out) = draw_through(
                    &mut **r,
                    &exposure.sample.q,
                    &intr,
                    exposure.level,
                    &noise,
                    &mut self.lens,
                );
                out
            }
            Backend::Mujoco(r) => {
                r.set_capture_tick(tick); // the `orbit` Sun at this capture
                draw_through(
                    &mut **r,
                    &exposure.sample.q,
                    &intr,
                    exposure.level,
                    &noise,
                    &mut self.lens,
                )
                .map_err(|e| e.to_string())?
            }
        };
        Ok(Rendered { exposure, image, truth, noise })
    }
}

/// The readout thread's state: applies the depth model and delivers.
struct Readout {
    frames: Sender<(RgbdFrame, RenderTruth)>,
    dropped: Arc<AtomicU64>,
    backlog: RenderBacklog,
}

impl Readout {
    fn run(self, images: Receiver<Rendered>) {
        while let Ok(Rendered { exposure, mut image, truth, mut noise }) = images.recv() {
            noise.apply_depth(&mut image.depth_m, &image.intrinsics);
            let Exposure { request, sample, exposure_ns, level } = exposure;
            let frame = RgbdFrame {
                request,
                device_ns: (sample.sim_time_s.max(0.0) * 1e9) as u64,
                exposure_ns,
                timestamp: TimestampSource::DeviceExposure,
                intrinsics: image.intrinsics,
                color: Arc::new(image.color),
                depth_m: Arc::new(image.depth_m),
                mask: Some(Arc::new(image.mask)),
            };
            let truth = RenderTruth {
                tick: request.tick,
                sim_time_s: sample.sim_time_s,
                light_level: level,
                ..truth
            };
            if self.frames.try_send((frame, truth)).is_err() {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
            self.backlog.finished();
        }
    }
}

/// Ray-cast one capture at joints `q` with the frame's noise; the truth's tick and time are left
/// for the caller to fill.
pub fn render_capture(
    renderer: &mut Renderer,
    q: &Joints,
    intr: &Intrinsics,
    level: f32,
    noise: &mut FrameNoise,
) -> (Image, RenderTruth) {
    let Ok(out) = capture_with(renderer, q, intr, level, noise);
    out
}

/// Render one capture with `renderer` at joints `q` with the frame's noise; the truth's tick
/// and time are left for the caller to fill. Through `intr`'s lens, if it has one.
pub fn capture_with<R: Draw + ?Sized>(
    renderer: &mut R,
    q: &Joints,
    intr: &Intrinsics,
    level: f32,
    noise: &mut FrameNoise,
) -> Result<(Image, RenderTruth), R::Error> {
    capture_through(renderer, q, intr, level, noise, &mut LensCache::default())
}

/// [`capture_with`], keeping the lens's remap in `lens` for the next capture: a pinhole is
/// rendered directly; a distorted stream is rendered on its pinhole canvas and remapped
/// ([`lens`]).
pub fn capture_through<R: Draw + ?Sized>(
    renderer: &mut R,
    q: &Joints,
    intr: &Intrinsics,
    level: f32,
    noise: &mut FrameNoise,
    lens: &mut LensCache,
) -> Result<(Image, RenderTruth), R::Error> {
    let (mut image, truth) = draw_through(renderer, q, intr, level, noise, lens)?;
    noise.apply_depth(&mut image.depth_m, &image.intrinsics);
    Ok((image, truth))
}

/// [`capture_through`] before the depth model: the image as rendered through the lens with the
/// frame's pose and principal point noise, and its truth.
fn draw_through<R: Draw + ?Sized>(
    renderer: &mut R,
    q: &Joints,
    intr: &Intrinsics,
    level: f32,
    noise: &FrameNoise,
    lens: &mut LensCache,
) -> Result<(Image, RenderTruth), R::Error> {
    renderer.set_joints(q);
    let camera = renderer.camera_in_lab();
    let rendered = camera * noise.rotation;
    let image = match lens.get(intr) {
        None => renderer.render_from(&rendered, intr, level, noise.shift_px)?,
        Some(map) => {
            map.remap(&renderer.render_from(&rendered, &map.canvas, level, noise.shift_px)?)
        }
    };
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
    Ok((image, truth))
}
