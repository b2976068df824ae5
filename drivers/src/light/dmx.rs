//! DMX512 light through an Enttec DMX USB Pro widget: frame encoding and the [`Light`] driver.
//!
//! The widget takes "Output Only Send DMX Packet Request" messages (label 6): `0x7E`, label,
//! data length LSB, MSB, data, `0xE7`, where the data is the DMX start code (0x00) followed by the
//! channel values. The light's level sits at a configurable start address, 8-bit (1.0 = 255) or
//! 16-bit (coarse channel then fine channel, 1.0 = 65535).
//!
//! The tick only stores the level into a lock-free slot; a tokio task picks it up every
//! `poll` period, writes a frame when the level changed (at most one per `min_interval`), and
//! refreshes the universe every `refresh` period (DMX receivers expect a continuous stream). Write
//! errors, write timeouts and hang-ups trip the sticky health flag, which the next call from the
//! tick ([`Light::set_level`] or [`Lifecycle::health`]) returns as an error.
//!
//! The task runs on the run's tokio runtime for as long as the light is in use: the runtime must
//! outlive the handle. [`Lifecycle::stop`] has the task write the current level one last time
//! and close the port, and waits for it (the widget keeps sending its last frame after that).

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;
use std::time::Duration;

use hitl_hal::{ErrorKind, ErrorType, Lifecycle, Light};
use tokio::task::JoinHandle;

use super::fault::{Fault, Health, SerialError, TaskAlive, TaskEnd};
use super::serial::{check_level, open_port, write_within};

/// Start-of-message delimiter of the Enttec DMX USB Pro API.
pub const ENTTEC_START: u8 = 0x7E;
/// End-of-message delimiter of the Enttec DMX USB Pro API.
pub const ENTTEC_END: u8 = 0xE7;
/// Label 6: Output Only Send DMX Packet Request.
pub const LABEL_SEND_DMX: u8 = 6;
/// DMX512 null start code (dimmer data).
pub const DMX_START_CODE: u8 = 0x00;
/// Channels in one DMX universe.
pub const UNIVERSE: u16 = 512;
/// The widget wants at least 24 channels after the start code.
pub const MIN_CHANNELS: u16 = 24;
/// The largest message: 4 header bytes, start code, 512 channels, end byte.
pub const MAX_MESSAGE: usize = 4 + 1 + UNIVERSE as usize + 1;

/// How many channels carry the level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DmxResolution {
    /// One channel, 1.0 = 255.
    #[default]
    Bits8,
    /// Two channels, coarse then fine, 1.0 = 65535.
    Bits16,
}

impl DmxResolution {
    pub fn channels(self) -> u16 {
        match self {
            DmxResolution::Bits8 => 1,
            DmxResolution::Bits16 => 2,
        }
    }
}

/// Settings of a DMX light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DmxConfig {
    /// DMX address (1-based) of the light's level channel.
    pub start_address: u16,
    pub resolution: DmxResolution,
    /// Channels sent per frame (24..=512); must cover the level channel(s).
    pub universe_channels: u16,
    /// Resend the universe at least this often, even if nothing changed.
    pub refresh: Duration,
    /// How often the task looks at the level slot.
    pub poll: Duration,
    /// Never send frames closer than this (a full DMX universe takes about 23 ms on the wire;
    /// the widget cannot output faster).
    pub min_interval: Duration,
    /// A frame write that takes longer than this is a fault.
    pub write_timeout: Duration,
    /// Nominal baud rate (the widget's USB serial ignores it).
    pub baud: u32,
}

impl Default for DmxConfig {
    fn default() -> Self {
        Self {
            start_address: 1,
            resolution: DmxResolution::Bits8,
            universe_channels: UNIVERSE,
            refresh: Duration::from_millis(25),
            poll: Duration::from_millis(2),
            min_interval: Duration::from_millis(23),
            write_timeout: Duration::from_millis(200),
            baud: 57_600,
        }
    }
}

impl DmxConfig {
    /// Check addresses and periods; says what is wrong.
    pub fn validate(&self) -> Result<(), SerialError> {
        let bad = |m: String| Err(SerialError::new(ErrorKind::InvalidRequest, m));
        let last = u32::from(self.start_address) + u32::from(self.resolution.channels()) - 1;
        if self.start_address == 0 || last > u32::from(UNIVERSE) {
            return bad(format!(
                "DMX start address {} with {} channel(s) does not fit in 1..=512",
                self.start_address,
                self.resolution.channels()
            ));
        }
        if !(MIN_CHANNELS..=UNIVERSE).contains(&self.universe_channels) {
            return bad(format!(
                "DMX universe size {} is outside {MIN_CHANNELS}..=512",
                self.universe_channels
            ));
        }
        if last > u32::from(self.universe_channels) {
            return bad(format!(
                "DMX level channel {last} lies beyond the {} channels sent",
                self.universe_channels
            ));
        }
        if self.refresh.is_zero() || self.poll.is_zero() || self.write_timeout.is_zero() {
            return bad("DMX refresh, poll and write timeout must be positive".into());
        }
        Ok(())
    }
}

/// Channel values for `level` (clamped to [0, 1]), rounded to the nearest step.
pub fn level_to_channels(level: f32, resolution: DmxResolution) -> [u8; 2] {
    let l = if level.is_finite() { level.clamp(0.0, 1.0) } else { 0.0 };
    match resolution {
        DmxResolution::Bits8 => [(l * 255.0).round() as u8, 0],
        DmxResolution::Bits16 => {
            let v = (f64::from(l) * 65535.0).round() as u16;
            v.to_be_bytes()
        }
    }
}

/// Encode one label-6 message carrying `level` into `out`; returns the message length.
pub fn encode_frame(level: f32, config: &DmxConfig, out: &mut [u8; MAX_MESSAGE]) -> usize {
    let n = usize::from(config.universe_channels.clamp(MIN_CHANNELS, UNIVERSE));
    let data_len = n + 1;
    out[0] = ENTTEC_START;
    out[1] = LABEL_SEND_DMX;
    out[2] = (data_len & 0xFF) as u8;
    out[3] = (data_len >> 8) as u8;
    out[4] = DMX_START_CODE;
    out[5..5 + n].fill(0);
    let values = level_to_channels(level, config.resolution);
    let first = usize::from(config.start_address.max(1)) - 1;
    for (i, v) in values.iter().take(usize::from(config.resolution.channels())).enumerate() {
        if first + i < n {
            out[5 + first + i] = *v;
        }
    }
    out[5 + n] = ENTTEC_END;
    6 + n
}

struct Shared {
    health: Health,
    /// f32 bits of the latest level asked for by the tick.
    level: AtomicU32,
    /// Asked to write a last frame and end.
    stopping: AtomicBool,
}

/// A DMX512 light on an Enttec DMX USB Pro. Drop it to stop the refresh task (the widget then
/// keeps sending its last frame).
pub struct DmxLight {
    shared: Arc<Shared>,
    task: JoinHandle<()>,
    ended: TaskEnd,
    /// How long `stop` waits for the last frame.
    stop_timeout: Duration,
}

impl DmxLight {
    /// Open the widget at `path` and start the refresh task; must run inside a tokio runtime.
    /// The light starts at level 0.
    pub async fn open(path: &str, config: DmxConfig) -> Result<Self, SerialError> {
        config.validate()?;
        let port = open_port(path, config.baud, "DMX light (Enttec DMX USB Pro)")?;
        let shared = Arc::new(Shared {
            health: Health::new(),
            level: AtomicU32::new(0),
            stopping: AtomicBool::new(false),
        });
        let (alive, ended) = TaskEnd::new();
        let task = tokio::spawn(refresh_task(port, config, Arc::clone(&shared), alive));
        let stop_timeout = config.write_timeout + config.refresh + config.poll;
        Ok(Self { shared, task, ended, stop_timeout })
    }

    /// The fault the driver tripped on, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.shared.health.fault()
    }

    /// Healthy, or the sticky fault; a task that ended unasked (its runtime was shut down) is the
    /// fault [`Fault::TaskEnded`].
    fn check(&self) -> Result<(), SerialError> {
        if !self.shared.stopping.load(Ordering::Acquire) && self.ended.has_ended() {
            self.shared.health.trip(Fault::TaskEnded);
        }
        self.shared.health.check()
    }
}

impl Drop for DmxLight {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl ErrorType for DmxLight {
    type Error = SerialError;
}

impl Lifecycle for DmxLight {
    /// A fault the refresh task tripped on (unplugged, write timeout, I/O error).
    fn health(&mut self) -> Result<(), SerialError> {
        self.check()
    }

    /// Write the current level once more, close the port and end the task (bounded by the
    /// write timeout plus one refresh period).
    fn stop(&mut self) -> Result<(), SerialError> {
        self.shared.stopping.store(true, Ordering::Release);
        if self.ended.wait(self.stop_timeout) {
            Ok(())
        } else {
            self.task.abort();
            Err(SerialError::new(
                ErrorKind::Timeout,
                "DMX light: the last frame was not written in time; the task was aborted",
            ))
        }
    }
}

impl Light for DmxLight {
    fn set_level(&mut self, level: f32) -> Result<(), SerialError> {
        self.check()?;
        check_level(level)?;
        self.shared.level.store(level.to_bits(), Ordering::Release);
        Ok(())
    }
}

async fn refresh_task(
    mut port: tokio_serial::SerialStream,
    config: DmxConfig,
    shared: Arc<Shared>,
    _alive: TaskAlive,
) {
    let mut buf = [0u8; MAX_MESSAGE];
    let mut poll = tokio::time::interval(config.poll);
    poll.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut sent: Option<u32> = None;
    let mut last_write = tokio::time::Instant::now();
    loop {
        poll.tick().await;
        let stopping = shared.stopping.load(Ordering::Acquire);
        let bits = shared.level.load(Ordering::Acquire);
        let since = last_write.elapsed();
        let due = stopping
            || since >= config.refresh
            || (sent != Some(bits) && since >= config.min_interval);
        if sent.is_some() && !due {
            continue;
        }
        let n = encode_frame(f32::from_bits(bits), &config, &mut buf);
        if let Err(fault) = write_within(&mut port, &buf[..n], config.write_timeout).await {
            shared.health.trip(fault);
            return;
        }
        if stopping {
            return;
        }
        sent = Some(bits);
        last_write = tokio::time::Instant::now();
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn full_level_is_255_on_channel_one() {
        let cfg = DmxConfig::default();
        let mut out = [0u8; MAX_MESSAGE];
        let n = encode_frame(1.0, &cfg, &mut out);
        assert_eq!(n, 518);
        assert_eq!(&out[..6], &[0x7E, 6, 0x01, 0x02, 0x00, 255]);
        assert!(out[6..517].iter().all(|&b| b == 0));
        assert_eq!(out[517], 0xE7);
    }

    #[test]
    fn sixteen_bit_level_at_start_address() {
        let cfg = DmxConfig {
            start_address: 10,
            resolution: DmxResolution::Bits16,
            universe_channels: 24,
            ..DmxConfig::default()
        };
        cfg.validate().unwrap();
        let mut out = [0u8; MAX_MESSAGE];
        let n = encode_frame(0.5, &cfg, &mut out);
        assert_eq!(n, 30);
        assert_eq!(&out[..4], &[0x7E, 6, 25, 0]);
        // 0.5 * 65535 = 32767.5 -> 32768 = 0x8000, at channels 10 and 11 (data bytes 14, 15).
        assert_eq!(&out[14..16], &[0x80, 0x00]);
        assert_eq!(out[29], 0xE7);
    }

    #[test]
    fn level_rounds_to_nearest_step() {
        assert_eq!(level_to_channels(0.5, DmxResolution::Bits8)[0], 128);
        assert_eq!(level_to_channels(0.0, DmxResolution::Bits8)[0], 0);
        assert_eq!(level_to_channels(2.0, DmxResolution::Bits8)[0], 255);
        assert_eq!(level_to_channels(f32::NAN, DmxResolution::Bits8)[0], 0);
    }

    #[test]
    fn bad_addresses_are_refused_with_reasons() {
        let c = DmxConfig { start_address: 0, ..DmxConfig::default() };
        assert!(c.validate().unwrap_err().message().contains("start address 0"));
        let c = DmxConfig {
            start_address: 512,
            resolution: DmxResolution::Bits16,
            ..DmxConfig::default()
        };
        assert!(c.validate().is_err());
        let c = DmxConfig { start_address: 30, universe_channels: 24, ..DmxConfig::default() };
        assert!(c.validate().unwrap_err().message().contains("beyond"));
    }
}
