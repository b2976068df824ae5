//! The trigger box's line protocol, version 2 (docs/trigger-box-protocol.md): formatting host
//! commands into fixed buffers and parsing the box's lines (answers, input reports, the `V`
//! answer and `#` notices with the start banner). Pure functions over bytes, no I/O, no
//! allocation.

use core::fmt::Write as _;

use hitl_hal::TriggerLines;

/// Longest line either side may send, terminator included.
pub const MAX_LINE: usize = 64;
/// The protocol version this codec speaks (the `V` answer's `protocol`).
pub const PROTOCOL_VERSION: u16 = 2;
/// Bit of the camera trigger line in a fire mask.
pub const LINE_CAMERA: u8 = 1;
/// Bit of the light strobe line in a fire mask.
pub const LINE_LIGHT: u8 = 2;

/// A host command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `P <seq>`: are you there? (acked like any command)
    Ping,
    /// `F <seq> <tick> <mask>`: raise the lines in `mask` now.
    Fire { tick: u64, lines: TriggerLines },
    /// `L <seq> <permille>`: set the steady light level.
    Level { permille: u16 },
    /// `S <seq> <permille> <duration_us>`: one light flash.
    Strobe { permille: u16, duration_us: u32 },
    /// `V <seq>`: which protocol and firmware? (answered by a `V` line, not an `A`)
    Version,
}

/// A firmware version, `MAJOR.MINOR.PATCH`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct FirmwareVersion {
    pub major: u16,
    pub minor: u16,
    pub patch: u16,
}

impl core::fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// Why the box last restarted, as its banner says (`reset=<cause>`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetCause {
    Power,
    External,
    Brownout,
    Watchdog,
    /// `unknown` (a bootloader cleared the flags), or a word this codec does not know.
    Unknown,
}

impl ResetCause {
    pub fn as_str(self) -> &'static str {
        match self {
            ResetCause::Power => "power",
            ResetCause::External => "external",
            ResetCause::Brownout => "brownout",
            ResetCause::Watchdog => "watchdog",
            ResetCause::Unknown => "unknown",
        }
    }

    fn parse(word: &str) -> Self {
        match word {
            "power" => ResetCause::Power,
            "external" => ResetCause::External,
            "brownout" => ResetCause::Brownout,
            "watchdog" => ResetCause::Watchdog,
            _ => ResetCause::Unknown,
        }
    }
}

/// A `#` line: for people reading the port; the host acts only on the two it knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Notice {
    /// `# hitl-trigger-box <firmware> protocol <protocol> reset=<cause>`: the box has just
    /// started (its first line after every reset). `firmware`/`protocol` are `None` when the
    /// banner's fields do not parse (it still says the box restarted).
    Banner { firmware: Option<FirmwareVersion>, protocol: Option<u16>, reset: ResetCause },
    /// `# safe host-silent`: the box went to its fail-safe (camera low, light off) after a
    /// second without a command.
    HostSilent,
    /// Any other `#` line.
    Other,
}

/// A line from the box.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoxLine {
    /// `A <seq> <device_us>`: command `seq` done at `device_us` on the box's clock.
    Ack { seq: u32, device_us: u64 },
    /// `I <device_us> <estop> <door>`: safety inputs (1 = pressed / open).
    Inputs { device_us: u64, estop_pressed: bool, door_open: bool },
    /// `E <seq> <code>`: command `seq` (0: none) failed with `code`.
    Error { seq: u32, code: u16 },
    /// `V <seq> <device_us> <protocol> <firmware>`: the answer to `V <seq>`, done at
    /// `device_us` (answers its `seq` like an `A`).
    Version { seq: u32, device_us: u64, protocol: u16, firmware: FirmwareVersion },
    /// `# <text>`: a notice (ignored by the protocol, but the banner means the box restarted).
    Notice(Notice),
}

/// `E` code: bad syntax or an over-long line.
pub const ERR_SYNTAX: u16 = 1;
/// `E` code: unknown command (a protocol-1 box answers `V` with it).
pub const ERR_UNKNOWN: u16 = 2;
/// `E` code: busy (a line asked for is still high, or the box's command queue is full; `seq` 0).
/// Never a fault: the command is retried.
pub const ERR_BUSY: u16 = 3;

/// Why a line from the box was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParseError {
    Empty,
    NotAscii,
    UnknownType,
    BadField,
    MissingField,
    ExtraField,
}

/// Mask bits for `lines`.
pub fn lines_mask(lines: TriggerLines) -> u8 {
    (if lines.camera { LINE_CAMERA } else { 0 }) | (if lines.light { LINE_LIGHT } else { 0 })
}

/// A level in [0, 1] as permille, rounded.
pub fn level_permille(level: f32) -> u16 {
    let l = if level.is_finite() { level.clamp(0.0, 1.0) } else { 0.0 };
    (l * 1000.0).round() as u16
}

/// Format `cmd` with sequence number `seq` as one `\n`-terminated line.
pub fn format_command(seq: u32, cmd: Command) -> heapless::String<MAX_LINE> {
    let mut s = heapless::String::new();
    // Longest line: "S 4294967295 1000 4294967295\n" (29 bytes), "F" with a u64 tick is 44:
    // every command fits in MAX_LINE, so the writes cannot fail.
    let _ = match cmd {
        Command::Ping => writeln!(s, "P {seq}"),
        Command::Fire { tick, lines } => writeln!(s, "F {seq} {tick} {}", lines_mask(lines)),
        Command::Level { permille } => writeln!(s, "L {seq} {permille}"),
        Command::Strobe { permille, duration_us } => {
            writeln!(s, "S {seq} {permille} {duration_us}")
        }
        Command::Version => writeln!(s, "V {seq}"),
    };
    s
}

/// `MAJOR.MINOR.PATCH`, each a decimal u16.
fn firmware_version(f: Option<&str>) -> Result<FirmwareVersion, ParseError> {
    let f = f.ok_or(ParseError::MissingField)?;
    let mut parts = f.split('.');
    let mut next = || field::<u16>(Some(parts.next().ok_or(ParseError::BadField)?));
    let v = FirmwareVersion { major: next()?, minor: next()?, patch: next()? };
    if parts.next().is_some() {
        return Err(ParseError::BadField);
    }
    Ok(v)
}

/// A `#` line's meaning (its bytes already checked).
fn notice(text: &str) -> Notice {
    let body = text.trim_start_matches('#').trim_start_matches(' ');
    if body == "safe host-silent" {
        return Notice::HostSilent;
    }
    let Some(rest) = body.strip_prefix("hitl-trigger-box") else { return Notice::Other };
    if !(rest.is_empty() || rest.starts_with(' ')) {
        return Notice::Other;
    }
    let words: heapless::Vec<&str, 8> = rest.split(' ').filter(|w| !w.is_empty()).take(8).collect();
    let firmware = words.first().and_then(|w| firmware_version(Some(w)).ok());
    let protocol = words
        .iter()
        .position(|w| *w == "protocol")
        .and_then(|i| words.get(i + 1))
        .and_then(|w| field::<u16>(Some(w)).ok());
    let reset = words
        .iter()
        .find_map(|w| w.strip_prefix("reset="))
        .map_or(ResetCause::Unknown, ResetCause::parse);
    Notice::Banner { firmware, protocol, reset }
}

fn field<T: core::str::FromStr>(f: Option<&str>) -> Result<T, ParseError> {
    let f = f.ok_or(ParseError::MissingField)?;
    if f.is_empty() || !f.bytes().all(|b| b.is_ascii_digit()) {
        return Err(ParseError::BadField);
    }
    f.parse().map_err(|_| ParseError::BadField)
}

fn flag(f: Option<&str>) -> Result<bool, ParseError> {
    match f.ok_or(ParseError::MissingField)? {
        "0" => Ok(false),
        "1" => Ok(true),
        _ => Err(ParseError::BadField),
    }
}

/// Parse one line from the box (without its `\n`; a trailing `\r` is allowed).
pub fn parse_line(line: &[u8]) -> Result<BoxLine, ParseError> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if line.is_empty() {
        return Err(ParseError::Empty);
    }
    if !line.iter().all(|b| (0x20..0x7F).contains(b)) {
        return Err(ParseError::NotAscii);
    }
    let text = core::str::from_utf8(line).map_err(|_| ParseError::NotAscii)?;
    if text.starts_with('#') {
        return Ok(BoxLine::Notice(notice(text)));
    }
    let mut parts = text.split(' ');
    let parsed = match parts.next() {
        Some("A") => BoxLine::Ack { seq: field(parts.next())?, device_us: field(parts.next())? },
        Some("I") => BoxLine::Inputs {
            device_us: field(parts.next())?,
            estop_pressed: flag(parts.next())?,
            door_open: flag(parts.next())?,
        },
        Some("E") => BoxLine::Error { seq: field(parts.next())?, code: field(parts.next())? },
        Some("V") => BoxLine::Version {
            seq: field(parts.next())?,
            device_us: field(parts.next())?,
            protocol: field(parts.next())?,
            firmware: firmware_version(parts.next())?,
        },
        _ => return Err(ParseError::UnknownType),
    };
    if parts.next().is_some() {
        return Err(ParseError::ExtraField);
    }
    Ok(parsed)
}

/// Splits a byte stream into lines with a bounded buffer.
#[derive(Debug, Default)]
pub struct LineBuffer {
    buf: heapless::Vec<u8, MAX_LINE>,
    overflowed: bool,
}

/// One step of [`LineBuffer::push`].
#[derive(Debug, PartialEq, Eq)]
pub enum Pushed<'a> {
    /// Need more bytes.
    Partial,
    /// A complete line (without `\n`).
    Line(&'a [u8]),
    /// The line exceeded [`MAX_LINE`].
    TooLong,
}

impl LineBuffer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Feed one byte. After `Line` the caller must call [`LineBuffer::clear`] before pushing more.
    pub fn push(&mut self, byte: u8) -> Pushed<'_> {
        if byte == b'\n' {
            if self.overflowed {
                self.clear();
                return Pushed::TooLong;
            }
            return Pushed::Line(&self.buf);
        }
        // Keep one byte of MAX_LINE for the terminator.
        if self.buf.len() + 1 >= MAX_LINE || self.buf.push(byte).is_err() {
            self.overflowed = true;
            return Pushed::TooLong;
        }
        Pushed::Partial
    }

    pub fn clear(&mut self) {
        self.buf.clear();
        self.overflowed = false;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn commands_format_as_documented() {
        let fire = Command::Fire { tick: 1234, lines: TriggerLines { camera: true, light: true } };
        assert_eq!(format_command(7, fire).as_str(), "F 7 1234 3\n");
        assert_eq!(format_command(1, Command::Ping).as_str(), "P 1\n");
        assert_eq!(format_command(2, Command::Level { permille: 500 }).as_str(), "L 2 500\n");
        let strobe = Command::Strobe { permille: 1000, duration_us: 2000 };
        assert_eq!(format_command(3, strobe).as_str(), "S 3 1000 2000\n");
        let big =
            Command::Fire { tick: u64::MAX, lines: TriggerLines { camera: true, light: false } };
        assert_eq!(format_command(u32::MAX, big).as_str(), "F 4294967295 18446744073709551615 1\n");
        assert_eq!(format_command(9, Command::Version).as_str(), "V 9\n");
    }

    #[test]
    fn version_answers_parse() {
        let v = FirmwareVersion { major: 0, minor: 1, patch: 0 };
        assert_eq!(
            parse_line(b"V 2 310551 2 0.1.0"),
            Ok(BoxLine::Version { seq: 2, device_us: 310_551, protocol: 2, firmware: v })
        );
        assert_eq!(v.to_string(), "0.1.0");
        assert_eq!(parse_line(b"V 2 310551 2"), Err(ParseError::MissingField));
        assert_eq!(parse_line(b"V 2 310551 2 0.1"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"V 2 310551 2 0.1.0.4"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"V 2 310551 2 0.x.0"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"V 2 310551 2 0.1.0 x"), Err(ParseError::ExtraField));
    }

    #[test]
    fn notices_parse_and_the_banner_says_why_the_box_restarted() {
        let fw = Some(FirmwareVersion { major: 0, minor: 1, patch: 0 });
        assert_eq!(
            parse_line(b"# hitl-trigger-box 0.1.0 protocol 2 reset=watchdog\r"),
            Ok(BoxLine::Notice(Notice::Banner {
                firmware: fw,
                protocol: Some(2),
                reset: ResetCause::Watchdog
            }))
        );
        // A banner whose fields do not parse still says the box restarted.
        assert_eq!(
            parse_line(b"# hitl-trigger-box ? reset=brown"),
            Ok(BoxLine::Notice(Notice::Banner {
                firmware: None,
                protocol: None,
                reset: ResetCause::Unknown
            }))
        );
        assert_eq!(parse_line(b"# safe host-silent"), Ok(BoxLine::Notice(Notice::HostSilent)));
        assert_eq!(parse_line(b"# anything else"), Ok(BoxLine::Notice(Notice::Other)));
        assert_eq!(parse_line(b"#"), Ok(BoxLine::Notice(Notice::Other)));
        assert_eq!(parse_line(b"# hitl-trigger-boxes"), Ok(BoxLine::Notice(Notice::Other)));
        // Still length- and ASCII-checked like every line.
        assert_eq!(parse_line(b"# caf\xc3\xa9"), Err(ParseError::NotAscii));
        let mut lb = LineBuffer::new();
        let mut long = false;
        for &b in [b'#'; 80].iter().chain(b"\n") {
            long |= lb.push(b) == Pushed::TooLong;
        }
        assert!(long, "a 80-byte notice is over-long");
    }

    #[test]
    fn box_lines_parse() {
        assert_eq!(parse_line(b"A 5 1000000"), Ok(BoxLine::Ack { seq: 5, device_us: 1_000_000 }));
        assert_eq!(
            parse_line(b"I 42 1 0\r"),
            Ok(BoxLine::Inputs { device_us: 42, estop_pressed: true, door_open: false })
        );
        assert_eq!(parse_line(b"E 0 3"), Ok(BoxLine::Error { seq: 0, code: 3 }));
    }

    #[test]
    fn garbage_is_rejected() {
        assert_eq!(parse_line(b""), Err(ParseError::Empty));
        assert_eq!(parse_line(b"X 1 2"), Err(ParseError::UnknownType));
        assert_eq!(parse_line(b"A 1"), Err(ParseError::MissingField));
        assert_eq!(parse_line(b"A 1 2 3"), Err(ParseError::ExtraField));
        assert_eq!(parse_line(b"A -1 2"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"A +1 2"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"I 1 2 0"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"A 99999999999 2"), Err(ParseError::BadField));
        assert_eq!(parse_line(b"A  1 2"), Err(ParseError::BadField));
        assert_eq!(parse_line(&[b'A', b' ', 0xFF]), Err(ParseError::NotAscii));
    }

    #[test]
    fn line_buffer_is_bounded() {
        let mut lb = LineBuffer::new();
        for &b in b"A 1 2" {
            assert_eq!(lb.push(b), Pushed::Partial);
        }
        assert_eq!(lb.push(b'\n'), Pushed::Line(b"A 1 2"));
        lb.clear();
        let mut too_long = false;
        for _ in 0..100 {
            too_long |= lb.push(b'x') == Pushed::TooLong;
        }
        assert!(too_long);
        assert_eq!(lb.push(b'\n'), Pushed::TooLong);
        assert_eq!(lb.push(b'A'), Pushed::Partial);
    }

    proptest::proptest! {
        /// Well-formed box lines parse back to exactly what was written (`\r\n` too).
        #[test]
        fn box_lines_round_trip(
            seq in proptest::num::u32::ANY,
            us in proptest::num::u64::ANY,
            estop in proptest::bool::ANY,
            door in proptest::bool::ANY,
            code in proptest::num::u16::ANY,
            crlf in proptest::bool::ANY,
        ) {
            let end = if crlf { "\r" } else { "" };
            let ack = format!("A {seq} {us}{end}");
            proptest::prop_assert_eq!(parse_line(ack.as_bytes()), Ok(BoxLine::Ack { seq, device_us: us }));
            let inputs = format!("I {us} {} {}{end}", u8::from(estop), u8::from(door));
            proptest::prop_assert_eq!(
                parse_line(inputs.as_bytes()),
                Ok(BoxLine::Inputs { device_us: us, estop_pressed: estop, door_open: door })
            );
            let err = format!("E {seq} {code}{end}");
            proptest::prop_assert_eq!(parse_line(err.as_bytes()), Ok(BoxLine::Error { seq, code }));
            let firmware = FirmwareVersion { major: code, minor: code / 7, patch: u16::from(crlf) };
            let v = format!("V {seq} {us} {code} {firmware}{end}");
            proptest::prop_assert_eq!(
                parse_line(v.as_bytes()),
                Ok(BoxLine::Version { seq, device_us: us, protocol: code, firmware })
            );
        }

        /// Any byte stream through the line buffer: lines never longer than MAX_LINE, and
        /// every line parses or is refused with a typed error.
        #[test]
        fn any_stream_splits_into_bounded_lines(
            bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..400)
        ) {
            let mut lb = LineBuffer::new();
            for b in bytes {
                if let Pushed::Line(l) = lb.push(b) {
                    proptest::prop_assert!(l.len() < MAX_LINE);
                    let _ = parse_line(l);
                    lb.clear();
                }
            }
        }

        #[test]
        fn parse_never_panics(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..80)) {
            let _ = parse_line(&bytes);
            let mut lb = LineBuffer::new();
            for b in bytes {
                if let Pushed::Line(l) = lb.push(b) {
                    let _ = parse_line(l);
                    lb.clear();
                }
            }
        }
    }
}
