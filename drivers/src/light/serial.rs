//! Opening serial ports for the light drivers and classifying their I/O errors as faults.

use std::io;
use std::time::Duration;

use hitl_hal::ErrorKind;
use tokio::io::{AsyncWrite, AsyncWriteExt};
use tokio_serial::{SerialPortBuilderExt, SerialStream};

use super::fault::{Fault, SerialError};

/// Open `path` as a raw 8N1 serial port registered with the current tokio runtime.
pub fn open_port(path: &str, baud: u32, what: &str) -> Result<SerialStream, SerialError> {
    if path.is_empty() {
        return Err(SerialError::new(
            ErrorKind::InvalidRequest,
            format!("{what}: empty serial port path"),
        ));
    }
    tokio_serial::new(path, baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(|e| {
            let kind = match e.kind {
                tokio_serial::ErrorKind::NoDevice => ErrorKind::NotFound,
                tokio_serial::ErrorKind::Io(io::ErrorKind::NotFound) => ErrorKind::NotFound,
                tokio_serial::ErrorKind::InvalidInput => ErrorKind::InvalidRequest,
                _ => ErrorKind::NotFound,
            };
            SerialError::new(kind, format!("{what}: cannot open serial port {path}: {e}"))
        })
}

/// What an I/O error on a serial port means: EIO / broken pipe / EOF are a hang-up (unplug).
pub fn classify_io(e: &io::Error) -> Fault {
    const EIO: i32 = 5;
    const ENXIO: i32 = 6;
    const ENODEV: i32 = 19;
    match e.raw_os_error() {
        Some(EIO | ENXIO | ENODEV) => Fault::Unplugged,
        _ => match e.kind() {
            io::ErrorKind::BrokenPipe
            | io::ErrorKind::UnexpectedEof
            | io::ErrorKind::NotConnected
            | io::ErrorKind::ConnectionReset => Fault::Unplugged,
            _ => Fault::Io,
        },
    }
}

/// Write all of `bytes` within `timeout`, or say which fault stopped it.
pub async fn write_within<W: AsyncWrite + Unpin>(
    w: &mut W,
    bytes: &[u8],
    timeout: Duration,
) -> Result<(), Fault> {
    match tokio::time::timeout(timeout, w.write_all(bytes)).await {
        Err(_) => Err(Fault::WriteTimeout),
        Ok(Err(e)) => Err(classify_io(&e)),
        Ok(Ok(())) => Ok(()),
    }
}

/// Check a level from the tick: finite and within [0, 1].
pub fn check_level(level: f32) -> Result<(), SerialError> {
    if level.is_finite() && (0.0..=1.0).contains(&level) {
        Ok(())
    } else {
        Err(SerialError::new(
            ErrorKind::InvalidRequest,
            "light level must be a finite number in [0, 1]",
        ))
    }
}
