//! Intrinsics presets of the simulated camera (OpenCV pinhole model; a lab's `[camera]
//! distortion` is added by the camera) and their check. Scaling to other resolutions is
//! [`Intrinsics::scaled`]'s one rule.

use hitl_hal::Intrinsics;

/// A named set of intrinsics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preset {
    /// The paper's narrow field of view: 1280x1024, f = 7315 px, principal point (640, 512).
    Nfov,
    /// The paper's wide field of view: 1280x1024, f = 1545 px, principal point (640, 512).
    Wfov,
    /// The Orbbec camera's stream, as its driver defines it
    /// ([`hitl_drivers::orbbec::profiles::GEMINI_STREAM`]: 1280x800, f = 640 px).
    Orbbec,
}

impl Preset {
    /// Parse `nfov`, `wfov` or `orbbec`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "nfov" => Some(Self::Nfov),
            "wfov" => Some(Self::Wfov),
            "orbbec" => Some(Self::Orbbec),
            _ => None,
        }
    }

    /// The preset at its native resolution.
    pub fn intrinsics(self) -> Intrinsics {
        match self {
            Self::Nfov => square(1280, 1024, 7315.0, 640.0, 512.0),
            Self::Wfov => square(1280, 1024, 1545.0, 640.0, 512.0),
            Self::Orbbec => hitl_drivers::orbbec::profiles::GEMINI_STREAM,
        }
    }

    /// The preset scaled to `width` x `height` (same field of view; [`Intrinsics::scaled`]).
    pub fn at(self, width: u32, height: u32) -> Intrinsics {
        self.intrinsics().scaled(width, height)
    }
}

fn square(width: u32, height: u32, f: f64, cx: f64, cy: f64) -> Intrinsics {
    Intrinsics::pinhole(width, height, f, f, cx, cy)
}

/// Largest image side the simulated camera renders.
pub const MAX_SIDE: u32 = 8192;

/// Why intrinsics were refused, or `None` when they make sense.
pub fn check(intr: &Intrinsics) -> Option<String> {
    if intr.width == 0 || intr.height == 0 || intr.width > MAX_SIDE || intr.height > MAX_SIDE {
        return Some(format!(
            "image size {}x{} must be between 1 and {MAX_SIDE} on each side",
            intr.width, intr.height
        ));
    }
    let finite = [intr.fx, intr.fy, intr.cx, intr.cy].iter().all(|v| v.is_finite());
    if !finite || intr.fx <= 0.0 || intr.fy <= 0.0 {
        return Some(format!(
            "focal lengths must be positive and all intrinsics finite (fx {}, fy {}, cx {}, cy {})",
            intr.fx, intr.fy, intr.cx, intr.cy
        ));
    }
    if !intr.distortion.is_finite() {
        return Some(format!("distortion coefficients must be finite ({:?})", intr.distortion.d()));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaling_keeps_the_field_of_view() {
        let n = Preset::Wfov.at(320, 256);
        assert_eq!((n.width, n.height), (320, 256));
        // (640 + 0.5) / 4 - 0.5: the principal point keeps its place in the image.
        assert!((n.fx - 1545.0 / 4.0).abs() < 1e-12 && (n.cx - 159.625).abs() < 1e-12);
        assert!((n.cy - 127.625).abs() < 1e-12);
        let full = Preset::Nfov.intrinsics();
        // The paper's FOV column is the vertical one: 2 atan(512 / f).
        let vfov = (512.0_f64 / full.fy).atan().to_degrees() * 2.0;
        assert!((vfov - 8.0).abs() < 0.05, "{vfov}");
        let w = Preset::Wfov.intrinsics();
        let vfov = (512.0_f64 / w.fy).atan().to_degrees() * 2.0;
        assert!((vfov - 36.5).abs() < 0.3, "{vfov}");
        assert_eq!(full.fx, 7315.0);
    }

    #[test]
    fn refuses_nonsense() {
        let mut i = Preset::Orbbec.intrinsics();
        assert!(check(&i).is_none());
        i.fx = -1.0;
        assert!(check(&i).is_some());
        i = Preset::Orbbec.at(0, 10);
        assert!(check(&i).is_some());
    }
}
