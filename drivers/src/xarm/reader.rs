//! The report-stream reader: a thread of its own reads a report port and turns each frame into
//! an [`ArmState`] stamped with the host's monotonic clock. Implements [`hitl_hal::ArmReports`].
//!
//! For a servo stream the reader uses port 30003 (100 Hz: state, mode, joints). That report has
//! no error codes, so the reader also keeps a side connection to 30001 (5 Hz) and merges its
//! latest error and warning codes into every state it returns. A real box stops the arm on any
//! error, so the state (4, stopped) shows the fault at 100 Hz and the code follows within 200 ms.
//!
//! A frame whose state, mode or sensitivities are out of range, or whose size differs from the
//! stream's first, is an error (a fault of the link), never data: the official SDK closes the
//! stream on such frames.

use super::codec::CodecError;
use super::error::XarmError;
use super::framing::FrameAccumulator;
use super::report::{decode_report, report_frame_len, ReportKind, MAX_REPORT_LEN};
use hitl_hal::{ArmReports, ArmState, Clock, ErrorType, MonotonicClock};
use socket2::{Domain, Protocol, Socket, Type};
use std::io;
use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

const RX_CAP: usize = 2 * MAX_REPORT_LEN;

/// Report-reader settings.
#[derive(Debug, Clone)]
pub struct ReportConfig {
    /// Which report to follow (default 30003, the real report).
    pub kind: ReportKind,
    /// Its port (default: the kind's port).
    pub port: Option<u16>,
    /// Port of a normal report (30001) read for the error/warning codes; `None` to skip.
    pub codes_port: Option<u16>,
    pub connect_timeout: Duration,
    /// How long `next_report` waits for a frame before failing with a timeout.
    pub read_timeout: Duration,
    /// The clock `received_ns` is counted on (pass the controller's clock).
    pub clock: MonotonicClock,
}

impl Default for ReportConfig {
    fn default() -> Self {
        Self {
            kind: ReportKind::Real,
            port: None,
            codes_port: Some(ReportKind::Normal.default_port()),
            connect_timeout: Duration::from_secs(2),
            read_timeout: Duration::from_millis(500),
            clock: MonotonicClock::new(),
        }
    }
}

/// A connected report stream.
#[derive(Debug)]
pub struct ReportReader {
    sock: Socket,
    kind: ReportKind,
    rx: FrameAccumulator<RX_CAP>,
    codes: Option<(Socket, FrameAccumulator<RX_CAP>)>,
    last_codes: (u8, u8),
    /// Size of the first frame of each stream (report, codes): a box never changes it.
    first_size: Option<usize>,
    first_codes_size: Option<usize>,
    seq: u64,
    clock: MonotonicClock,
}

fn connect(addr: SocketAddr, timeout: Duration) -> Result<Socket, XarmError> {
    let err = |source| XarmError::Connect { addr, source };
    let sock =
        Socket::new(Domain::for_address(addr), Type::STREAM, Some(Protocol::TCP)).map_err(err)?;
    sock.connect_timeout(&addr.into(), timeout).map_err(err)?;
    sock.set_tcp_nodelay(true).map_err(err)?;
    Ok(sock)
}

fn fill(rx: &mut FrameAccumulator<RX_CAP>, sock: &Socket) -> Result<(), XarmError> {
    let mut s = sock;
    match rx.fill_from(&mut s) {
        Ok(0) => Err(XarmError::Closed),
        Ok(_) => Ok(()),
        Err(e) if e.kind() == io::ErrorKind::InvalidData => {
            Err(CodecError::Overflow(rx.pending()).into())
        }
        Err(e) => Err(XarmError::Io(e)),
    }
}

impl ReportReader {
    /// Connect to the report port(s) of the box at `host`.
    pub fn connect(host: IpAddr, config: ReportConfig) -> Result<Self, XarmError> {
        let port = config.port.unwrap_or(config.kind.default_port());
        let sock = connect(SocketAddr::new(host, port), config.connect_timeout)?;
        sock.set_read_timeout(Some(config.read_timeout))?;
        let codes = match config.codes_port {
            Some(p) if !config.kind.has_codes() => {
                let s = connect(SocketAddr::new(host, p), config.connect_timeout)?;
                s.set_nonblocking(true)?;
                Some((s, FrameAccumulator::new()))
            }
            _ => None,
        };
        Ok(Self {
            sock,
            kind: config.kind,
            rx: FrameAccumulator::new(),
            codes,
            last_codes: (0, 0),
            first_size: None,
            first_codes_size: None,
            seq: 0,
            clock: config.clock,
        })
    }

    /// Reports returned so far.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// Take the newest codes from the side connection without blocking.
    fn poll_codes(&mut self) -> Result<(), XarmError> {
        let Some((sock, rx)) = self.codes.as_mut() else { return Ok(()) };
        loop {
            while rx.poll_frame(report_frame_len)?.is_some() {
                same_size(&mut self.first_codes_size, rx.frame().len())?;
                let r = decode_report(rx.frame(), ReportKind::Normal)?;
                self.last_codes = (r.error_code, r.warn_code);
            }
            match fill(rx, sock) {
                Ok(()) => {}
                Err(XarmError::Io(e)) if e.kind() == io::ErrorKind::WouldBlock => return Ok(()),
                Err(e) => return Err(e),
            }
        }
    }
}

/// A stream's frames all have the size of its first (the SDK closes a stream whose size changes).
fn same_size(first: &mut Option<usize>, got: usize) -> Result<(), CodecError> {
    match *first {
        None => {
            *first = Some(got);
            Ok(())
        }
        Some(f) if f == got => Ok(()),
        Some(f) => Err(CodecError::ReportSizeChanged { first: f, got }),
    }
}

impl ErrorType for ReportReader {
    type Error = XarmError;
}

impl ArmReports for ReportReader {
    fn next_report(&mut self) -> Result<ArmState, XarmError> {
        loop {
            if self.rx.poll_frame(report_frame_len)?.is_some() {
                let received_ns = self.clock.now_ns();
                same_size(&mut self.first_size, self.rx.frame().len())?;
                let r = decode_report(self.rx.frame(), self.kind)?;
                if self.kind.has_codes() {
                    self.last_codes = (r.error_code, r.warn_code);
                } else {
                    self.poll_codes()?;
                }
                self.seq += 1;
                return Ok(ArmState {
                    received_ns,
                    q: r.q,
                    state: r.state,
                    mode: r.mode,
                    error_code: self.last_codes.0,
                    warn_code: self.last_codes.1,
                    seq: self.seq,
                });
            }
            fill(&mut self.rx, &self.sock)?;
        }
    }
}
