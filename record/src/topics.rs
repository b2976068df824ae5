//! Topic names of the MCAP contract and the JSON Schemas of the project's own messages.

pub const SETPOINT: &str = "/arm/setpoint";
pub const STATE: &str = "/arm/state";
pub const TIMING: &str = "/loop/timing";
pub const LIGHT: &str = "/light/state";
pub const EVENT: &str = "/safety/event";
pub const TF: &str = "/tf";
pub const POSE_GT: &str = "/pose/gt";
pub const POSE_ESTIMATE: &str = "/pose/estimate";
pub const COLOR: &str = "/camera/color";
pub const DEPTH: &str = "/camera/depth";
pub const MASK: &str = "/camera/mask";
pub const CALIBRATION: &str = "/camera/calibration";
/// Extension: each frame's trigger and exposure times and their difference (the sync error).
pub const CAPTURE_SYNC: &str = "/camera/sync";
/// Extension: every trigger-line fire the trigger box acknowledged (its own fire time).
pub const TRIGGER_FIRED: &str = "/trigger/fired";
/// Extension: the recorder's own counters, once a second and at close.
pub const RECORDER_STATS: &str = "/recorder/stats";
/// Extension (`hitl run --closed-loop`): the relative-navigation filter's state and covariance
/// after each estimate.
pub const CLOSED_LOOP_FILTER: &str = "/closed_loop/filter";
/// Extension (`--closed-loop`): each correction sent to the tick, or refused.
pub const CLOSED_LOOP_CORRECTION: &str = "/closed_loop/correction";
/// Extension (`--closed-loop`): each capture's gating decision (used, or why not).
pub const CLOSED_LOOP_GATE: &str = "/closed_loop/gate";

/// Metadata record names.
pub const META_RUN: &str = "run";
/// Extension: the Sun phase schedule of the trajectory (keys `t_s`, `sun_phase_deg`: JSON arrays).
pub const META_SUN_PHASE: &str = "sun_phase";
/// Extension: final counters, written at a clean close.
pub const META_RECORDER_STATS: &str = "recorder_stats";

/// Frame ids used in `/tf`, images and poses.
pub const FRAME_BASE: &str = "base";
pub const FRAME_FLANGE: &str = "flange";
pub const FRAME_CAMERA: &str = "camera";
pub const FRAME_TARGET: &str = "target";

const Q7: &str = r#"{"type":"array","items":{"type":"number"},"minItems":7,"maxItems":7}"#;

/// (schema name, JSON Schema) for a JSON topic.
pub(crate) fn json_schema(topic: &str) -> Option<(&'static str, String)> {
    let s = match topic {
        SETPOINT => (
            "hitl.Setpoint",
            format!(
                r#"{{"type":"object","properties":{{"tick":{{"type":"integer"}},"t_ns":{{"type":"integer"}},"phase":{{"type":"string","enum":["approach","lead_in","playback","lead_out","stop","retreat"]}},"q":{Q7},"qd":{Q7}}},"required":["tick","t_ns","phase","q","qd"]}}"#
            ),
        ),
        STATE => (
            "hitl.ArmState",
            format!(
                r#"{{"type":"object","properties":{{"t_ns":{{"type":"integer"}},"q":{Q7},"state":{{"type":"integer"}},"mode":{{"type":"integer"}},"error_code":{{"type":"integer"}},"warn_code":{{"type":"integer"}}}},"required":["t_ns","q","state","mode","error_code","warn_code"]}}"#
            ),
        ),
        TIMING => (
            "hitl.LoopTiming",
            r#"{"type":"object","properties":{"tick":{"type":"integer"},"t_ns":{"type":"integer"},"wake_late_ns":{"type":"integer"},"tick_ns":{"type":"integer"},"overrun":{"type":"boolean"}},"required":["tick","t_ns","wake_late_ns","tick_ns","overrun"]}"#.to_string(),
        ),
        LIGHT => (
            "hitl.LightState",
            r#"{"type":"object","properties":{"t_ns":{"type":"integer"},"level":{"type":"number","minimum":0,"maximum":1}},"required":["t_ns","level"]}"#.to_string(),
        ),
        EVENT => (
            "hitl.SafetyEvent",
            r#"{"type":"object","properties":{"t_ns":{"type":"integer"},"kind":{"type":"string"},"detail":{"type":"string"},"tick":{"type":"integer"},"joint":{"type":"integer"},"value":{"type":"number"},"limit":{"type":"number"}},"required":["t_ns","kind","detail"]}"#.to_string(),
        ),
        CAPTURE_SYNC => (
            "hitl.CaptureSync",
            r#"{"type":"object","properties":{"tick":{"type":"integer"},"trigger_ns":{"type":"integer"},"exposure_ns":{"type":"integer"},"sync_error_ns":{"type":"integer"}},"required":["tick","trigger_ns","exposure_ns","sync_error_ns"]}"#.to_string(),
        ),
        TRIGGER_FIRED => (
            "hitl.TriggerFired",
            r#"{"type":"object","properties":{"t_ns":{"type":"integer"},"tick":{"type":"integer"},"device_us":{"type":"integer"},"fired_ns":{"type":"integer"},"clock_error_ns":{"type":"integer"}},"required":["t_ns","tick","device_us"]}"#.to_string(),
        ),
        RECORDER_STATS => (
            "hitl.RecorderStats",
            r#"{"type":"object","properties":{"t_ns":{"type":"integer"},"written":{"type":"object","additionalProperties":{"type":"integer"}},"dropped":{"type":"object","additionalProperties":{"type":"integer"}},"frames_not_recorded":{"type":"integer"},"bytes_in":{"type":"integer"}},"required":["written","dropped","frames_not_recorded"]}"#.to_string(),
        ),
        CLOSED_LOOP_FILTER => (
            "hitl.ClosedLoopFilter",
            r#"{"type":"object","properties":{"tick":{"type":"integer"},"t_orbit_s":{"type":"number"},"state":{"type":"array","items":{"type":"number"},"minItems":6,"maxItems":6},"covariance":{"type":"array","items":{"type":"number"},"minItems":36,"maxItems":36},"deviation_lab_m":{"type":"array","items":{"type":"number"},"minItems":3,"maxItems":3}},"required":["tick","state","covariance"]}"#.to_string(),
        ),
        CLOSED_LOOP_CORRECTION => (
            "hitl.ClosedLoopCorrection",
            r#"{"type":"object","properties":{"tick":{"type":"integer"},"id":{"type":"integer"},"based_on":{"type":"integer"},"correction_lab_m":{"type":"array","items":{"type":"number"}},"clamped":{"type":"boolean"},"ticks":{"type":"integer"},"return_to_plan":{"type":"boolean"},"refused":{"type":"string"}},"required":["tick"]}"#.to_string(),
        ),
        CLOSED_LOOP_GATE => (
            "hitl.ClosedLoopGate",
            r#"{"type":"object","properties":{"tick":{"type":"integer"},"used":{"type":"boolean"},"reason":{"type":"string","enum":["accepted","lost","late","gated","missing"]},"mahalanobis2":{"type":["number","null"]},"in_a_row":{"type":"integer"},"measured_lab_m":{"type":"array","items":{"type":"number"}}},"required":["tick","used","reason"]}"#.to_string(),
        ),
        _ => return None,
    };
    Some(s)
}
