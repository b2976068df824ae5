//! The studio light and the trigger box on serial lines.
//!
//! - [`dmx`]: DMX512 through an Enttec DMX USB Pro widget ([`DmxLight`], a [`hitl_hal::Light`]);
//! - [`enttec`]: what the widget sends back (framing decoder, parameters and serial replies) and
//!   [`enttec::probe_widget`] for commissioning;
//! - [`trigger_box`]: the project's microcontroller trigger box ([`TriggerBox`]: camera trigger
//!   and light strobe lines, light level, e-stop and door inputs), protocol in [`protocol`] and
//!   docs/trigger-box-protocol.md, and the box's clock on the host's in [`clock_map`];
//! - [`spec`]: the `--light sim|dmx:DEV|trigger:DEV|none` choice ([`LightSpec`]) and the registry
//!   that opens a serial light as trait objects ([`OpenedLight`]): a new kind of light is its
//!   driver file plus its arms in `spec.rs`;
//! - [`fault`]: the drivers' error type and sticky lock-free health flag.
//!
//! Every driver here is a tick-side handle that only touches atomics and lock-free queues, plus a
//! tokio task that owns the port; the caller's runtime must outlive the handle (it is the run's
//! runtime, kept for the whole run). Each driver implements [`hitl_hal::Lifecycle`]: `health`
//! from the tick, `stop` after the loop. See docs/lights.md and docs/devices.md.

pub mod clock_map;
pub mod dmx;
pub mod enttec;
pub mod fault;
pub mod protocol;
pub mod serial;
pub mod spec;
pub mod trigger_box;

pub use dmx::{DmxConfig, DmxLight, DmxResolution};
pub use fault::{Fault, SerialError};
pub use spec::{
    InputsDriver, LightDriver, LightSpec, OpenedLight, OpenedTrigger, TriggerDriver, TriggerSpec,
};
pub use trigger_box::{BoxVersion, BusyCounts, TriggerBox, TriggerBoxConfig};

#[cfg(test)]
mod tests {
    /// The tick-side handles move to the real-time thread.
    #[test]
    fn handles_are_send() {
        fn send<T: Send + 'static>() {}
        send::<super::DmxLight>();
        send::<super::TriggerBox>();
    }
}
