//! `hitl-record`: the crash-safe MCAP recording of a run, its reader, and the run report.
//!
//! The control loop pushes telemetry into [`Telemetry`] (bounded lock-free queues, never
//! blocking: a full queue drops its oldest message and counts it) and frames through a separate
//! small queue (a frame that cannot be queued becomes a `capture-not-recorded` safety event).
//! The [`Recorder`] thread drains them into an MCAP file whose topics are the contract in
//! docs/architecture.md (see docs/mcap-topics.md), closing a chunk at least every 250 ms so a killed
//! process loses at most that. [`RecorderHealth::is_failed`] tells the tick when the file can
//! no longer be written so the interlock can trip.
//!
//! Inside the writing side, imports go one way, from the thread down to the bytes:
//! `recorder` (the thread, its queues and health) -> `sink` (the MCAP file) -> `live` (the live
//! view's tap, offered every message the sink writes) -> `channels` (topics, schemas, shared
//! encodings) -> `msg`, `topics`, `error` -> `summary`. Nothing lower imports anything higher.

pub mod bench;
mod channels;
pub mod compression;
pub mod error;
pub mod health;
pub mod live;
pub mod metadata;
pub mod msg;
pub mod queues;
pub mod reader;
pub mod recorder;
pub mod report;
mod sink;
pub mod summary;
pub mod topics;

pub use compression::{ChunkCompression, CompressionParseError};
pub use error::{ReadError, RecordError};
pub use health::RecorderHealth;
pub use live::{LiveConfig, LiveError, LiveServer, LiveSummary, LiveTap};
pub use metadata::{RunMetadata, SunPhaseTrack};
pub use msg::{
    ArmStateMsg, CaptureSyncMsg, ClosedLoopMsg, ClosedLoopTopic, DepthImage, EventDetail,
    EventKind, FrameRecord, LightMsg, Phase, Plane, PoseStamped, SafetyEventMsg, SetpointMsg,
    TfMsg, TimingMsg, TriggerFiredMsg,
};
pub use queues::{QueueCapacity, Telemetry};
pub use recorder::{Recorder, RecorderConfig, RecorderHandle};
pub use sink::DepthOutput;
pub use summary::RecordSummary;
