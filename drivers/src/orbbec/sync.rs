//! How the camera is told to expose: the sync modes Orbbec DOCUMENTS for each camera (a table
//! by USB product id), and the choice between hardware triggering (the camera's sync input
//! driven by the trigger box's camera line) and software triggering (`ob_device_trigger_capture`).
//!
//! The SDK's own bitmap (`ob_device_get_supported_multi_device_sync_mode_bitmap`) is not enough:
//! 2.9.3 advertises software triggering for the Gemini 305g, whose documentation lists only
//! secondary-synced and hardware triggering. A mode is used only when it is both documented here
//! and advertised by the SDK.

use std::fmt;

use hitl_hal::ErrorKind;

use super::error::OrbbecError;

/// `OB_MULTI_DEVICE_SYNC_MODE_*` bits (ObTypes.h).
pub const MODE_FREE_RUN: u16 = 1 << 0;
pub const MODE_STANDALONE: u16 = 1 << 1;
pub const MODE_PRIMARY: u16 = 1 << 2;
pub const MODE_SECONDARY: u16 = 1 << 3;
pub const MODE_SECONDARY_SYNCED: u16 = 1 << 4;
pub const MODE_SOFTWARE_TRIGGERING: u16 = 1 << 5;
pub const MODE_HARDWARE_TRIGGERING: u16 = 1 << 6;

/// One camera model's documented sync capabilities.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DocumentedModel {
    pub product_id: u16,
    pub name: &'static str,
    /// `MODE_*` bits listed in Orbbec's multi-device sync documentation for this model.
    pub sync_modes: u16,
}

/// Orbbec's documented sync modes by product id (Gemini 305 family, SDK 2.9.3).
pub const DOCUMENTED: &[DocumentedModel] = &[
    DocumentedModel {
        product_id: 0x0840,
        name: "Gemini 305",
        sync_modes: MODE_PRIMARY
            | MODE_SECONDARY_SYNCED
            | MODE_SOFTWARE_TRIGGERING
            | MODE_HARDWARE_TRIGGERING,
    },
    DocumentedModel {
        product_id: 0x0841,
        name: "Gemini 305",
        sync_modes: MODE_PRIMARY
            | MODE_SECONDARY_SYNCED
            | MODE_SOFTWARE_TRIGGERING
            | MODE_HARDWARE_TRIGGERING,
    },
    DocumentedModel {
        product_id: 0x0842,
        name: "Gemini 305g",
        sync_modes: MODE_SECONDARY_SYNCED | MODE_HARDWARE_TRIGGERING,
    },
];

/// The documented model with this product id, if any.
pub fn documented(product_id: u16) -> Option<&'static DocumentedModel> {
    DOCUMENTED.iter().find(|m| m.product_id == product_id)
}

/// The names of the `MODE_*` bits set in `bits`, e.g. "software-triggering, hardware-triggering".
pub fn mode_names(bits: u16) -> String {
    const NAMES: [(u16, &str); 7] = [
        (MODE_FREE_RUN, "free-run"),
        (MODE_STANDALONE, "standalone"),
        (MODE_PRIMARY, "primary"),
        (MODE_SECONDARY, "secondary"),
        (MODE_SECONDARY_SYNCED, "secondary-synced"),
        (MODE_SOFTWARE_TRIGGERING, "software-triggering"),
        (MODE_HARDWARE_TRIGGERING, "hardware-triggering"),
    ];
    let v: Vec<&str> = NAMES.iter().filter(|(b, _)| bits & b != 0).map(|(_, n)| *n).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

/// The camera's multi-device sync configuration (`ob_multi_device_sync_config`), as the driver
/// reads it at open, writes its own at arm, and writes the one it found back at close.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncConfig {
    /// One `MODE_*` bit (the factory default is free-run).
    pub mode: u16,
    pub depth_delay_us: i32,
    pub color_delay_us: i32,
    pub trigger_to_image_delay_us: i32,
    /// Whether the camera passes each trigger on at its sync output (to a chained camera).
    pub trigger_out_enable: bool,
    pub trigger_out_delay_us: i32,
    pub frames_per_trigger: i32,
}

impl SyncConfig {
    /// The configuration hitl plays with: `mode`, one frame per trigger, no delays, and the
    /// trigger output as asked (off for a single camera: nothing is chained to it).
    pub fn for_run(mode: TriggerMode, trigger_out: bool) -> Self {
        Self {
            mode: mode.bit(),
            depth_delay_us: 0,
            color_delay_us: 0,
            trigger_to_image_delay_us: 0,
            trigger_out_enable: trigger_out,
            trigger_out_delay_us: 0,
            frames_per_trigger: 1,
        }
    }

    /// Whether the camera waits for triggers in this mode (it then sends no frame on its own:
    /// other tools see a silent camera).
    pub fn is_triggered(&self) -> bool {
        self.mode & (MODE_SOFTWARE_TRIGGERING | MODE_HARDWARE_TRIGGERING) != 0
    }
}

impl fmt::Display for SyncConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}, {} frame(s) per trigger, trigger out {}, delays: trigger to image {} us, depth \
             {} us, colour {} us",
            mode_names(self.mode),
            self.frames_per_trigger,
            if self.trigger_out_enable {
                format!("on (+{} us)", self.trigger_out_delay_us)
            } else {
                "off".into()
            },
            self.trigger_to_image_delay_us,
            self.depth_delay_us,
            self.color_delay_us
        )
    }
}

/// How a capture starts an exposure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriggerMode {
    /// The camera's sync input (Gemini 305: USB-C pins A8/B8) driven by the trigger box's
    /// camera line; the driver only waits for the frameset.
    Hardware,
    /// The driver sends `ob_device_trigger_capture` for every capture request.
    Software,
}

impl TriggerMode {
    pub fn bit(self) -> u16 {
        match self {
            TriggerMode::Hardware => MODE_HARDWARE_TRIGGERING,
            TriggerMode::Software => MODE_SOFTWARE_TRIGGERING,
        }
    }
}

impl fmt::Display for TriggerMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            TriggerMode::Hardware => "hardware triggering",
            TriggerMode::Software => "software triggering",
        })
    }
}

/// What the operator asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TriggerChoice {
    /// Hardware triggering where documented and advertised, else software triggering where
    /// documented and advertised.
    #[default]
    Auto,
    Hardware,
    Software,
}

/// The trigger mode for a camera with `product_id` whose SDK advertises `advertised` (bits).
pub fn choose_trigger(
    product_id: u16,
    advertised: u16,
    choice: TriggerChoice,
) -> Result<TriggerMode, OrbbecError> {
    let Some(model) = documented(product_id) else {
        return Err(OrbbecError::new(
            ErrorKind::InvalidRequest,
            format!(
                "Orbbec camera with product id {product_id:#06x} has no documented sync modes in \
                 this driver (documented: Gemini 305 0x0840/0x0841, Gemini 305g 0x0842); the SDK \
                 advertises: {}",
                mode_names(advertised)
            ),
        ));
    };
    let usable = model.sync_modes & advertised;
    let wanted: &[TriggerMode] = match choice {
        TriggerChoice::Auto => &[TriggerMode::Hardware, TriggerMode::Software],
        TriggerChoice::Hardware => &[TriggerMode::Hardware],
        TriggerChoice::Software => &[TriggerMode::Software],
    };
    wanted.iter().copied().find(|m| usable & m.bit() != 0).ok_or_else(|| {
        OrbbecError::new(
            ErrorKind::InvalidRequest,
            format!(
                "Orbbec {} ({product_id:#06x}) cannot use {}: documented sync modes: {}; the SDK \
                 advertises: {}",
                model.name,
                match choice {
                    TriggerChoice::Software => "software triggering",
                    _ => "hardware triggering",
                },
                mode_names(model.sync_modes),
                mode_names(advertised)
            ),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: u16 = 0x7F;

    #[test]
    fn the_305g_never_gets_software_triggering_even_when_advertised() {
        assert_eq!(choose_trigger(0x0842, ALL, TriggerChoice::Auto), Ok(TriggerMode::Hardware));
        let e = choose_trigger(0x0842, ALL, TriggerChoice::Software).expect_err("undocumented");
        assert!(e.message().contains("Gemini 305g"), "{e}");
        assert!(e.message().contains("documented sync modes: secondary-synced, hardware"), "{e}");
    }

    #[test]
    fn the_305_defaults_to_hardware_and_may_use_software() {
        for pid in [0x0840, 0x0841] {
            assert_eq!(choose_trigger(pid, ALL, TriggerChoice::Auto), Ok(TriggerMode::Hardware));
            assert_eq!(
                choose_trigger(pid, ALL, TriggerChoice::Software),
                Ok(TriggerMode::Software)
            );
            // Hardware not advertised (old firmware): Auto falls back to software.
            assert_eq!(
                choose_trigger(pid, MODE_SOFTWARE_TRIGGERING, TriggerChoice::Auto),
                Ok(TriggerMode::Software)
            );
            assert!(choose_trigger(pid, MODE_SOFTWARE_TRIGGERING, TriggerChoice::Hardware).is_err());
        }
    }

    #[test]
    fn an_undocumented_camera_is_refused_with_what_the_sdk_says() {
        let e = choose_trigger(0x0999, ALL, TriggerChoice::Auto).expect_err("unknown");
        assert!(e.message().contains("0x0999"), "{e}");
        assert!(e.message().contains("software-triggering"), "{e}");
    }
}
