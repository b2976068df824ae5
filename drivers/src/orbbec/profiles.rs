//! Which colour and depth streams to start: colour rgb8 at the asked size, depth Y16, both at ONE
//! explicitly chosen frame rate (never "any"), so every trigger exposes both at once and the
//! `Align` filter can put depth onto the colour image.

use std::fmt;

use hitl_hal::{ErrorKind, Intrinsics};

use super::error::OrbbecError;
use super::frame::{FORMAT_RGB, FORMAT_Y16};

/// The stream a run asks of an Orbbec Gemini-class camera by default (`--camera-preset orbbec`):
/// 1280x800, f = 640 px (about 90 x 64 degrees, the wide depth field of the Gemini 2/300 family),
/// principal point at the image centre. Typical values, not a calibration of any unit; the
/// simulated camera's `orbbec` preset is this stream.
pub const GEMINI_STREAM: Intrinsics = Intrinsics::pinhole(1280, 800, 640.0, 640.0, 640.0, 400.0);

/// Frame rates tried first, in this order (the Gemini 305's common rates); then the highest
/// rate both streams share.
pub const PREFERRED_FPS: [u32; 3] = [30, 15, 60];

/// One video stream profile: size, `ob_format` and frame rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VideoProfile {
    pub width: u32,
    pub height: u32,
    pub format: i32,
    pub fps: u32,
}

impl fmt::Display for VideoProfile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self.format {
            FORMAT_RGB => "RGB",
            FORMAT_Y16 => "Y16",
            28 => "Z16",
            5 => "MJPG",
            0 => "YUYV",
            _ => "format",
        };
        write!(f, "{}x{} {name}({}) @{} fps", self.width, self.height, self.format, self.fps)
    }
}

/// Colour RGB at `width x height` and a Y16 depth profile at the same frame rate: the depth
/// profile of the colour's size if there is one, else the largest at that rate.
pub fn choose_profiles(
    color: &[VideoProfile],
    depth: &[VideoProfile],
    width: u32,
    height: u32,
) -> Result<(VideoProfile, VideoProfile), OrbbecError> {
    let colors: Vec<&VideoProfile> = color
        .iter()
        .filter(|p| p.format == FORMAT_RGB && p.width == width && p.height == height && p.fps > 0)
        .collect();
    if colors.is_empty() {
        return Err(OrbbecError::new(
            ErrorKind::InvalidRequest,
            format!(
                "Orbbec camera has no RGB colour stream at {width}x{height}; it offers: {}",
                list(color)
            ),
        ));
    }
    let depth_at = |fps: u32| -> Option<VideoProfile> {
        let at: Vec<&VideoProfile> =
            depth.iter().filter(|p| p.format == FORMAT_Y16 && p.fps == fps).collect();
        at.iter()
            .find(|p| p.width == width && p.height == height)
            .or_else(|| at.iter().max_by_key(|p| u64::from(p.width) * u64::from(p.height)))
            .map(|p| **p)
    };
    let mut rates: Vec<u32> = colors.iter().map(|p| p.fps).collect();
    rates.sort_unstable_by(|a, b| b.cmp(a));
    let order = PREFERRED_FPS.iter().copied().filter(|f| rates.contains(f)).chain(rates.clone());
    for fps in order {
        if let (Some(c), Some(d)) = (colors.iter().find(|p| p.fps == fps), depth_at(fps)) {
            return Ok((**c, d));
        }
    }
    Err(OrbbecError::new(
        ErrorKind::InvalidRequest,
        format!(
            "Orbbec camera has no Y16 depth stream at a frame rate of the RGB {width}x{height} \
             colour stream ({rates:?} fps); depth offers: {}",
            list(depth)
        ),
    ))
}

fn list(p: &[VideoProfile]) -> String {
    if p.is_empty() {
        return "nothing".into();
    }
    p.iter().map(|p| p.to_string()).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(width: u32, height: u32, format: i32, fps: u32) -> VideoProfile {
        VideoProfile { width, height, format, fps }
    }

    #[test]
    fn one_frame_rate_for_both_and_same_size_depth_first() {
        let color =
            [p(1280, 720, FORMAT_RGB, 60), p(1280, 720, FORMAT_RGB, 30), p(640, 480, 5, 30)];
        let depth = [
            p(848, 480, FORMAT_Y16, 30),
            p(1280, 720, FORMAT_Y16, 30),
            p(1280, 720, FORMAT_Y16, 15),
            p(640, 400, FORMAT_Y16, 60),
        ];
        let (c, d) = choose_profiles(&color, &depth, 1280, 720).expect("profiles");
        assert_eq!(c, p(1280, 720, FORMAT_RGB, 30));
        assert_eq!(d, p(1280, 720, FORMAT_Y16, 30));
    }

    #[test]
    fn without_a_same_size_depth_the_largest_at_that_rate() {
        let color = [p(640, 480, FORMAT_RGB, 15)];
        let depth = [
            p(320, 200, FORMAT_Y16, 15),
            p(848, 480, FORMAT_Y16, 15),
            p(1280, 800, FORMAT_Y16, 30),
        ];
        let (c, d) = choose_profiles(&color, &depth, 640, 480).expect("profiles");
        assert_eq!((c.fps, d), (15, p(848, 480, FORMAT_Y16, 15)));
    }

    #[test]
    fn no_shared_rate_or_size_is_a_clear_refusal() {
        let color = [p(640, 480, FORMAT_RGB, 30)];
        let depth = [p(640, 480, FORMAT_Y16, 15)];
        let e = choose_profiles(&color, &depth, 640, 480).expect_err("no shared rate");
        assert!(e.message().contains("no Y16 depth stream at a frame rate"), "{e}");
        let e = choose_profiles(&color, &depth, 320, 240).expect_err("no size");
        assert!(e.message().contains("640x480 RGB(22) @30 fps"), "{e}");
    }
}
