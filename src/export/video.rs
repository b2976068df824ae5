//! The image streams as video files, one per stream for the whole dataset (episodes follow each
//! other; the episodes table says where each starts), encoded by ffmpeg from raw frames on its
//! standard input so a frame is never held longer than it takes to convert it.
//!
//! - colour: H.264 (libx264), yuv420p (yuv444p when a side is odd), every other frame a key frame;
//! - depth: LeRobot v3.0's depth-map video: metres quantised to 12-bit codes on LeRobot's
//!   logarithmic scale ([`DepthQuant`]), lossless HEVC in `gray12le`;
//! - mask: lossless HEVC in `gray` (0 or 255 as recorded).
//!
//! Frame `i` of a file is presented at `i / fps` exactly, as the loader looks frames up.

use super::episode::{Episode, Stream};
use super::{io_err, ExportError};
use hitl_record::reader;
use std::collections::BTreeMap;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

/// LeRobot's depth quantiser (its defaults): depth `d` metres becomes the 12-bit code
/// `rint(4095 * (ln(d + shift) - ln(min + shift)) / (ln(max + shift) - ln(min + shift)))`, clipped
/// to 0..=4095; the loader inverts it with the parameters in the feature's `info`. No return
/// (0 or not finite) becomes code 0, which reads back as `min`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthQuant {
    pub min_m: f64,
    pub max_m: f64,
    pub shift_m: f64,
}

impl DepthQuant {
    pub const LEROBOT_DEFAULT: DepthQuant = DepthQuant { min_m: 0.01, max_m: 10.0, shift_m: 3.5 };
    pub const QMAX: u16 = 4095;

    pub fn code(&self, d_m: f32) -> u16 {
        let d = f64::from(d_m);
        if !d.is_finite() || d <= 0.0 {
            return 0;
        }
        let lo = (self.min_m + self.shift_m).ln();
        let hi = (self.max_m + self.shift_m).ln();
        let norm = ((d + self.shift_m).ln() - lo) / (hi - lo);
        (norm * f64::from(Self::QMAX)).round_ties_even().clamp(0.0, f64::from(Self::QMAX)) as u16
    }

    /// The depth a code reads back as, metres.
    pub fn depth_m(&self, code: u16) -> f64 {
        let lo = (self.min_m + self.shift_m).ln();
        let hi = (self.max_m + self.shift_m).ln();
        let d = (lo + f64::from(code) * (hi - lo) / f64::from(Self::QMAX)).exp() - self.shift_m;
        d.clamp(self.min_m, self.max_m)
    }
}

/// How a stream is encoded: what the info.json's `video.*` keys will say.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoFormat {
    pub codec: &'static str,
    pub pix_fmt: &'static str,
    pub channels: u32,
}

/// The format of each stream at a size.
pub fn format_of(stream: Stream, width: u32, height: u32) -> VideoFormat {
    match stream {
        Stream::Color => VideoFormat {
            codec: "h264",
            pix_fmt: if width.is_multiple_of(2) && height.is_multiple_of(2) {
                "yuv420p"
            } else {
                "yuv444p"
            },
            channels: 3,
        },
        Stream::Depth => VideoFormat { codec: "hevc", pix_fmt: "gray12le", channels: 1 },
        Stream::Mask => VideoFormat { codec: "hevc", pix_fmt: "gray", channels: 1 },
    }
}

/// Checks that `ffmpeg` runs and has the encoders the streams need.
pub fn check_ffmpeg(streams: impl IntoIterator<Item = Stream>) -> Result<(), ExportError> {
    let out = Command::new("ffmpeg")
        .args(["-hide_banner", "-encoders"])
        .stdin(Stdio::null())
        .output()
        .map_err(|e| {
            ExportError::Encoder(format!(
                "cannot run ffmpeg ({e}): install it (Debian: apt-get install ffmpeg; make setup does)"
            ))
        })?;
    let list = String::from_utf8_lossy(&out.stdout);
    for s in streams {
        let enc = encoder_name(s);
        if !list.split_whitespace().any(|w| w == enc) {
            return Err(ExportError::Encoder(format!(
                "ffmpeg has no {enc} encoder (needed for {}); Debian's ffmpeg has it",
                s.topic()
            )));
        }
    }
    Ok(())
}

fn encoder_name(s: Stream) -> &'static str {
    match s {
        Stream::Color => "libx264",
        Stream::Depth | Stream::Mask => "libx265",
    }
}

/// One running ffmpeg, fed raw frames.
struct Encoder {
    child: Child,
    stdin: Option<ChildStdin>,
    log: PathBuf,
    out: PathBuf,
    frames: u64,
    buf: Vec<u8>,
}

impl Encoder {
    fn spawn(
        stream: Stream,
        (w, h): (u32, u32),
        fps: u32,
        out: &Path,
        log: &Path,
    ) -> Result<Encoder, ExportError> {
        let fmt = format_of(stream, w, h);
        let input_fmt = match stream {
            Stream::Color => "rgb24",
            Stream::Depth => "gray12le",
            Stream::Mask => "gray",
        };
        let size = format!("{w}x{h}");
        let rate = fps.to_string();
        let mut args: Vec<&str> = vec!["-hide_banner", "-loglevel", "error", "-y"];
        args.extend(["-f", "rawvideo", "-pix_fmt", input_fmt, "-s", &size, "-r", &rate]);
        args.extend(["-i", "pipe:0"]);
        match stream {
            Stream::Color => {
                args.extend(["-c:v", "libx264", "-preset", "veryfast", "-crf", "18"]);
                args.extend(["-g", "2", "-bf", "0"]);
            }
            Stream::Depth | Stream::Mask => {
                args.extend(["-c:v", "libx265", "-x265-params", "lossless=1:log-level=error"]);
            }
        }
        args.extend(["-pix_fmt", fmt.pix_fmt, "-an"]);
        let logf = std::fs::File::create(log).map_err(|e| io_err("cannot create", log, e))?;
        let mut child = Command::new("ffmpeg")
            .args(&args)
            .arg(out)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(logf)
            .spawn()
            .map_err(|e| ExportError::Encoder(format!("cannot start ffmpeg: {e}")))?;
        let stdin = child.stdin.take();
        Ok(Encoder {
            child,
            stdin,
            log: log.to_path_buf(),
            out: out.to_path_buf(),
            frames: 0,
            buf: Vec::new(),
        })
    }

    fn write(&mut self) -> Result<(), ExportError> {
        let Some(stdin) = self.stdin.as_mut() else {
            return Err(ExportError::Encoder("ffmpeg's input is closed".into()));
        };
        if let Err(e) = stdin.write_all(&self.buf) {
            let why = std::fs::read_to_string(&self.log).unwrap_or_default();
            return Err(ExportError::Encoder(format!(
                "ffmpeg stopped reading frames for {} ({e}): {}",
                self.out.display(),
                why.trim()
            )));
        }
        self.frames += 1;
        Ok(())
    }

    fn finish(mut self) -> Result<u64, ExportError> {
        drop(self.stdin.take());
        let status = self
            .child
            .wait()
            .map_err(|e| ExportError::Encoder(format!("waiting for ffmpeg: {e}")))?;
        if !status.success() {
            let why = std::fs::read_to_string(&self.log).unwrap_or_default();
            return Err(ExportError::Encoder(format!(
                "ffmpeg failed on {} ({status}): {}",
                self.out.display(),
                why.trim()
            )));
        }
        Ok(self.frames)
    }
}

impl Drop for Encoder {
    fn drop(&mut self) {
        // An export that failed half way: stop this ffmpeg rather than leave it waiting.
        if self.stdin.is_some() {
            drop(self.stdin.take());
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Convert one decoded image into the encoder's raw frame in `buf`.
fn convert(
    stream: Stream,
    img: &foxglove::messages::RawImage,
    quant: &DepthQuant,
    buf: &mut Vec<u8>,
) -> Result<(), String> {
    let (w, h, step) = (img.width as usize, img.height as usize, img.step as usize);
    buf.clear();
    match stream {
        Stream::Color => {
            if step < 3 * w || img.data.len() < step * h {
                return Err(format!("colour buffer of {} bytes for {w}x{h}", img.data.len()));
            }
            let bgr = img.encoding == "bgr8";
            for row in 0..h {
                let r = &img.data[row * step..row * step + 3 * w];
                if bgr {
                    r.chunks_exact(3).for_each(|p| buf.extend_from_slice(&[p[2], p[1], p[0]]));
                } else {
                    buf.extend_from_slice(r);
                }
            }
        }
        Stream::Mask => {
            if step < w || img.data.len() < step * h {
                return Err(format!("mask buffer of {} bytes for {w}x{h}", img.data.len()));
            }
            (0..h).for_each(|row| buf.extend_from_slice(&img.data[row * step..row * step + w]));
        }
        Stream::Depth => {
            let d = reader::depth_metres(img).ok_or_else(|| {
                format!("depth buffer of {} bytes does not match {w}x{h}", img.data.len())
            })?;
            d.iter().for_each(|&m| buf.extend_from_slice(&quant.code(m).to_le_bytes()));
        }
    }
    Ok(())
}

/// The video file of each stream, and how many frames each got.
pub struct Videos {
    pub files: BTreeMap<Stream, PathBuf>,
    pub frames: BTreeMap<Stream, u64>,
}

/// Encode every episode's frames, in order, into one file per stream (`path_of(stream)`).
/// Each episode's images are read from its recording in one pass.
pub fn encode(
    episodes: &[Episode],
    size: (u32, u32),
    fps: u32,
    quant: &DepthQuant,
    path_of: impl Fn(Stream) -> PathBuf,
    log_dir: &Path,
) -> Result<Videos, ExportError> {
    let streams = episodes.first().map(|e| e.streams.clone()).unwrap_or_default();
    let mut encoders = BTreeMap::new();
    let mut files = BTreeMap::new();
    for &s in &streams {
        let out = path_of(s);
        if let Some(dir) = out.parent() {
            std::fs::create_dir_all(dir).map_err(|e| io_err("cannot create", dir, e))?;
        }
        let log = log_dir.join(format!("ffmpeg-{s:?}.log").to_lowercase());
        encoders.insert(s, Encoder::spawn(s, size, fps, &out, &log)?);
        files.insert(s, out);
    }
    for ep in episodes {
        encode_episode(ep, quant, &mut encoders)?;
    }
    let mut frames = BTreeMap::new();
    for (s, e) in encoders {
        frames.insert(s, e.finish()?);
    }
    Ok(Videos { files, frames })
}

fn encode_episode(
    ep: &Episode,
    quant: &DepthQuant,
    encoders: &mut BTreeMap<Stream, Encoder>,
) -> Result<(), ExportError> {
    let shown = ep.path.display();
    // The next frame each stream expects; images of captures that are not frames are skipped.
    let mut next: BTreeMap<Stream, usize> = encoders.keys().map(|s| (*s, 0)).collect();
    let mut failure: Option<ExportError> = None;
    reader::visit(
        &ep.path,
        |m| {
            let Some(s) = Stream::ALL.into_iter().find(|s| s.topic() == m.topic) else {
                return ControlFlow::Continue(());
            };
            let (Some(i), Some(enc)) = (next.get_mut(&s), encoders.get_mut(&s)) else {
                return ControlFlow::Continue(());
            };
            let img = match reader::decode_image(m.data) {
                Ok(img) => img,
                Err(e) => {
                    failure = Some(ExportError::BadInput(format!("{shown}: {}: {e}", m.topic)));
                    return ControlFlow::Break(());
                }
            };
            let t = img.timestamp.map(|t| t.total_nanos()).unwrap_or(m.log_time);
            let Some(f) = ep.frames.get(*i) else { return ControlFlow::Continue(()) };
            if t != f.capture_ns {
                if ep.frames[*i..].iter().any(|f| f.capture_ns == t) {
                    failure = Some(ExportError::BadInput(format!(
                        "{shown}: {} images out of capture order at {t} ns",
                        m.topic
                    )));
                    return ControlFlow::Break(());
                }
                return ControlFlow::Continue(());
            }
            if let Err(e) = convert(s, &img, quant, &mut enc.buf) {
                failure = Some(ExportError::BadInput(format!("{shown}: {}: {e}", m.topic)));
                return ControlFlow::Break(());
            }
            if let Err(e) = enc.write() {
                failure = Some(e);
                return ControlFlow::Break(());
            }
            *i += 1;
            ControlFlow::Continue(())
        },
        |_, _| {},
    )
    .map_err(|e| ExportError::BadInput(e.to_string()))?;
    if let Some(e) = failure {
        return Err(e);
    }
    for (s, i) in next {
        if i != ep.frames.len() {
            return Err(ExportError::BadInput(format!(
                "{shown}: {} gave {i} of {} images on the second read",
                s.topic(),
                ep.frames.len()
            )));
        }
    }
    Ok(())
}
