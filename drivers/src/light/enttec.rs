//! Messages *from* an Enttec DMX USB Pro widget: a bounded stream decoder for the API's framing
//! (`0x7E`, label, length LSB, MSB, data, `0xE7`) and the replies the controller can ask for
//! (label 3, Get Widget Parameters Reply; label 10, Get Widget Serial Number Reply). The light
//! itself only writes (label 6); `hitl probe` asks the widget for its parameters to check that a
//! widget, not just a serial port, is there ([`probe_widget`]).
//!
//! Bytes from the widget are outside input: every sequence decodes to a message, a typed error,
//! or "need more bytes", never a panic, and the buffer never grows past [`MAX_DATA`].

use std::time::Duration;

use hitl_hal::ErrorKind;
use tokio::io::AsyncReadExt;

use super::dmx::{ENTTEC_END, ENTTEC_START};
use super::fault::SerialError;
use super::serial::{classify_io, open_port, write_within};

/// The longest data part the widget sends (a received DMX packet: status, start code, 512).
pub const MAX_DATA: usize = 600;
/// Label 3: Get Widget Parameters (request and reply).
pub const LABEL_PARAMETERS: u8 = 3;
/// Label 10: Get Widget Serial Number (request and reply).
pub const LABEL_SERIAL: u8 = 10;

/// One framed message from the widget.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Message {
    pub label: u8,
    pub data: heapless::Vec<u8, MAX_DATA>,
}

/// Why bytes from the widget were rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// A byte other than `0x7E` where a message should start (it was skipped).
    NoStart(u8),
    /// The announced data length exceeds [`MAX_DATA`] (the message was dropped).
    TooLong(usize),
    /// The byte after the data was not `0xE7` (the message was dropped).
    NoEnd(u8),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Start,
    Label,
    LenLo,
    LenHi { lo: u8 },
    Data,
    End,
}

/// Splits the widget's byte stream into [`Message`]s with a fixed buffer.
#[derive(Debug)]
pub struct Decoder {
    state: State,
    label: u8,
    len: usize,
    data: heapless::Vec<u8, MAX_DATA>,
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Decoder {
    pub fn new() -> Self {
        Self { state: State::Start, label: 0, len: 0, data: heapless::Vec::new() }
    }

    /// Feed one byte: `Ok(Some(message))` when it completes one, `Ok(None)` when more bytes are
    /// needed, `Err` when the byte broke the framing (the decoder is then looking for a start).
    pub fn push(&mut self, byte: u8) -> Result<Option<Message>, DecodeError> {
        match self.state {
            State::Start => {
                if byte != ENTTEC_START {
                    return Err(DecodeError::NoStart(byte));
                }
                self.state = State::Label;
            }
            State::Label => {
                self.label = byte;
                self.state = State::LenLo;
            }
            State::LenLo => self.state = State::LenHi { lo: byte },
            State::LenHi { lo } => {
                self.len = usize::from(lo) | usize::from(byte) << 8;
                if self.len > MAX_DATA {
                    self.state = State::Start;
                    return Err(DecodeError::TooLong(self.len));
                }
                self.data.clear();
                self.state = if self.len == 0 { State::End } else { State::Data };
            }
            State::Data => {
                // Cannot fail: len <= MAX_DATA was checked and the state ends at len.
                let _ = self.data.push(byte);
                if self.data.len() >= self.len {
                    self.state = State::End;
                }
            }
            State::End => {
                self.state = State::Start;
                if byte != ENTTEC_END {
                    return Err(DecodeError::NoEnd(byte));
                }
                return Ok(Some(Message { label: self.label, data: self.data.clone() }));
            }
        }
        Ok(None)
    }
}

/// What a reply says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reply {
    /// Label 3: firmware version, DMX break and mark-after-break (units of 10.67 µs), and the
    /// output rate in packets per second (0: as fast as possible).
    Parameters { firmware: u16, break_time: u8, mab_time: u8, rate: u8 },
    /// Label 10: the serial number (the widget sends it as BCD; this is its decimal value).
    Serial(u32),
    /// Any other label (the controller has no use for it).
    Other { label: u8 },
}

/// Why a message is not a valid reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplyError {
    /// Fewer data bytes than the label needs.
    Short { label: u8, len: usize },
    /// A serial number digit that is not BCD.
    NotBcd,
}

/// Interpret a decoded message.
pub fn parse_reply(m: &Message) -> Result<Reply, ReplyError> {
    let d = &m.data;
    let short = || ReplyError::Short { label: m.label, len: d.len() };
    match m.label {
        LABEL_PARAMETERS => {
            let [lo, hi, break_time, mab_time, rate, ..] = d[..] else { return Err(short()) };
            Ok(Reply::Parameters {
                firmware: u16::from_le_bytes([lo, hi]),
                break_time,
                mab_time,
                rate,
            })
        }
        LABEL_SERIAL => {
            let [a, b, c, e, ..] = d[..] else { return Err(short()) };
            let mut n = 0u32;
            // Least significant byte first, two BCD digits per byte.
            for byte in [e, c, b, a] {
                let (hi, lo) = (byte >> 4, byte & 0x0F);
                if hi > 9 || lo > 9 {
                    return Err(ReplyError::NotBcd);
                }
                n = n * 100 + u32::from(hi) * 10 + u32::from(lo);
            }
            Ok(Reply::Serial(n))
        }
        label => Ok(Reply::Other { label }),
    }
}

/// Decode every message in `bytes` (framing errors skipped): for tests and fuzzing.
pub fn decode_all(bytes: &[u8]) -> Vec<Result<Reply, ReplyError>> {
    let mut dec = Decoder::new();
    bytes.iter().filter_map(|&b| dec.push(b).ok().flatten()).map(|m| parse_reply(&m)).collect()
}

/// Open the widget at `path`, ask for its parameters (label 3) and wait up to `timeout` for the
/// reply: a widget answers, a plain serial port does not. Must run inside a tokio runtime; the
/// port is closed again on return (open the light afterwards).
pub async fn probe_widget(path: &str, timeout: Duration) -> Result<Reply, SerialError> {
    let mut port = open_port(path, 57_600, "DMX widget (Enttec DMX USB Pro)")?;
    let request = [ENTTEC_START, LABEL_PARAMETERS, 2, 0, 0, 0, ENTTEC_END];
    write_within(&mut port, &request, timeout).await.map_err(SerialError::from)?;
    let mut dec = Decoder::new();
    let mut buf = [0u8; 256];
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let n = match tokio::time::timeout_at(deadline, port.read(&mut buf)).await {
            Err(_) => {
                return Err(SerialError::new(
                    ErrorKind::Timeout,
                    format!(
                        "DMX widget on {path}: no parameters reply within {} ms (not an Enttec \
                         DMX USB Pro, or not powered?)",
                        timeout.as_millis()
                    ),
                ))
            }
            Ok(Ok(0)) => return Err(super::fault::Fault::Unplugged.into()),
            Ok(Ok(n)) => n,
            Ok(Err(e)) => return Err(classify_io(&e).into()),
        };
        for &b in &buf[..n] {
            if let Ok(Some(m)) = dec.push(b) {
                if m.label == LABEL_PARAMETERS {
                    return parse_reply(&m).map_err(|e| {
                        SerialError::new(
                            ErrorKind::Protocol,
                            format!("DMX widget on {path}: bad parameters reply: {e:?}"),
                        )
                    });
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_parameters_reply_decodes() {
        let bytes = [0x7E, 3, 5, 0, 0x44, 0x01, 9, 1, 40, 0xE7];
        assert_eq!(
            decode_all(&bytes),
            vec![Ok(Reply::Parameters { firmware: 0x0144, break_time: 9, mab_time: 1, rate: 40 })]
        );
    }

    #[test]
    fn a_serial_number_reply_decodes_from_bcd() {
        // 12345678 sent least significant byte first.
        let bytes = [0x7E, 10, 4, 0, 0x78, 0x56, 0x34, 0x12, 0xE7];
        assert_eq!(decode_all(&bytes), vec![Ok(Reply::Serial(12_345_678))]);
        let bad = [0x7E, 10, 4, 0, 0xFA, 0, 0, 0, 0xE7];
        assert_eq!(decode_all(&bad), vec![Err(ReplyError::NotBcd)]);
    }

    #[test]
    fn broken_framing_is_skipped_and_the_next_message_still_decodes() {
        let mut dec = Decoder::new();
        assert_eq!(dec.push(0x00), Err(DecodeError::NoStart(0)));
        for b in [0x7E, 3, 0xFF] {
            assert_eq!(dec.push(b), Ok(None));
        }
        assert_eq!(dec.push(0xFF), Err(DecodeError::TooLong(0xFFFF)));
        let short = [0x7E, 3, 1, 0, 7, 0xE7];
        assert_eq!(decode_all(&short), vec![Err(ReplyError::Short { label: 3, len: 1 })]);
        let no_end = [0x7E, 3, 0, 0, 0x00, 0x7E, 99, 0, 0, 0xE7];
        assert_eq!(decode_all(&no_end), vec![Ok(Reply::Other { label: 99 })]);
    }

    proptest::proptest! {
        /// Any bytes: messages, typed errors or "more bytes", never a panic; data never exceeds
        /// what the length announced, nor MAX_DATA.
        #[test]
        fn arbitrary_widget_bytes_never_panic(
            bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..1500)
        ) {
            let mut dec = Decoder::new();
            for b in bytes {
                if let Ok(Some(m)) = dec.push(b) {
                    proptest::prop_assert!(m.data.len() <= MAX_DATA);
                    let _ = parse_reply(&m);
                }
            }
        }

        /// Every well-formed message comes back exactly, whatever garbage precedes it.
        #[test]
        fn framed_messages_round_trip(
            junk in proptest::collection::vec(0u8..0x7E, 0..20),
            label in proptest::num::u8::ANY,
            data in proptest::collection::vec(proptest::num::u8::ANY, 0..MAX_DATA),
        ) {
            let mut bytes = junk;
            bytes.extend([ENTTEC_START, label, (data.len() & 0xFF) as u8, (data.len() >> 8) as u8]);
            bytes.extend(&data);
            bytes.push(ENTTEC_END);
            let mut dec = Decoder::new();
            let got: Vec<Message> = bytes.iter().filter_map(|&b| dec.push(b).ok().flatten()).collect();
            proptest::prop_assert_eq!(got.len(), 1);
            proptest::prop_assert_eq!(got[0].label, label);
            proptest::prop_assert_eq!(&got[0].data[..], &data[..]);
        }
    }
}
