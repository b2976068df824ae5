//! A fixed-capacity byte accumulator that cuts a TCP byte stream into frames.
//!
//! Bytes arrive in arbitrary pieces (partial reads, several frames coalesced in one read); the
//! accumulator keeps at most `CAP` bytes, asks a framing function how long the frame at its
//! front is, and hands out whole frames. It never grows: a frame that cannot fit is an error.

use super::codec::CodecError;
use std::io::{self, Read};

/// The declared length of the frame at the start of a buffer: `Ok(None)` = header incomplete.
pub type FrameLenFn = fn(&[u8]) -> Result<Option<usize>, CodecError>;

/// Bytes received but not yet consumed as frames, in a fixed array.
#[derive(Debug)]
pub struct FrameAccumulator<const CAP: usize> {
    buf: [u8; CAP],
    len: usize,
    /// Length of the frame at the front, once [`FrameAccumulator::poll_frame`] found one.
    ready: usize,
}

impl<const CAP: usize> Default for FrameAccumulator<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> FrameAccumulator<CAP> {
    pub const fn new() -> Self {
        Self { buf: [0; CAP], len: 0, ready: 0 }
    }

    /// Bytes held (including a frame not yet consumed).
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Forget everything (after a reconnect or a framing error).
    pub fn clear(&mut self) {
        self.len = 0;
        self.ready = 0;
    }

    /// Append bytes from a slice; fails (keeping nothing new) when they do not fit.
    pub fn push(&mut self, bytes: &[u8]) -> Result<(), CodecError> {
        self.consume_ready();
        let end = self.len + bytes.len();
        if end > CAP {
            return Err(CodecError::Overflow(end));
        }
        self.buf[self.len..end].copy_from_slice(bytes);
        self.len = end;
        Ok(())
    }

    /// Read once from `src` into the free space. `Ok(0)` means the peer closed the stream.
    /// Fails with `InvalidData` when the buffer is full without holding a complete frame.
    pub fn fill_from<R: Read>(&mut self, src: &mut R) -> io::Result<usize> {
        self.consume_ready();
        if self.len == CAP {
            return Err(io::Error::new(io::ErrorKind::InvalidData, CodecError::Overflow(CAP)));
        }
        let n = src.read(&mut self.buf[self.len..])?;
        self.len += n;
        Ok(n)
    }

    /// Find the next complete frame; returns its length. The frame stays available through
    /// [`FrameAccumulator::frame`] until the next `poll_frame`, `push` or `fill_from`.
    pub fn poll_frame(&mut self, frame_len: FrameLenFn) -> Result<Option<usize>, CodecError> {
        self.consume_ready();
        match frame_len(&self.buf[..self.len])? {
            Some(0) => Err(CodecError::Length(0)),
            Some(n) if n > CAP => Err(CodecError::Overflow(n)),
            Some(n) if n <= self.len => {
                self.ready = n;
                Ok(Some(n))
            }
            Some(_) => Ok(None),
            None if self.len == CAP => Err(CodecError::Overflow(CAP)),
            None => Ok(None),
        }
    }

    /// The frame found by the last successful [`FrameAccumulator::poll_frame`] (empty if none).
    pub fn frame(&self) -> &[u8] {
        &self.buf[..self.ready]
    }

    fn consume_ready(&mut self) {
        if self.ready > 0 {
            self.buf.copy_within(self.ready..self.len, 0);
            self.len -= self.ready;
            self.ready = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::xarm::codec::{frame_len, Accept};

    fn cmd(buf: &[u8]) -> Result<Option<usize>, CodecError> {
        frame_len(buf, Accept::Private)
    }

    #[test]
    fn partial_and_coalesced_frames() {
        let a = [0u8, 1, 0, 2, 0, 3, 13, 0, 2];
        let b = [0u8, 2, 0, 2, 0, 4, 15, 0x40, 23, 0];
        let mut stream = Vec::new();
        stream.extend_from_slice(&a);
        stream.extend_from_slice(&b);
        let mut acc = FrameAccumulator::<32>::new();
        acc.push(&stream[..4]).expect("fits");
        assert_eq!(acc.poll_frame(cmd), Ok(None));
        acc.push(&stream[4..]).expect("fits");
        assert_eq!(acc.poll_frame(cmd), Ok(Some(9)));
        assert_eq!(acc.frame(), &a);
        assert_eq!(acc.poll_frame(cmd), Ok(Some(10)));
        assert_eq!(acc.frame(), &b);
        assert_eq!(acc.poll_frame(cmd), Ok(None));
        assert_eq!(acc.pending(), 0);
    }

    #[test]
    fn overflow_is_an_error_not_growth() {
        let mut acc = FrameAccumulator::<8>::new();
        assert!(acc.push(&[0; 9]).is_err());
        acc.push(&[0, 1, 0, 2, 0, 100]).expect("fits");
        assert_eq!(acc.poll_frame(cmd), Err(CodecError::Overflow(106)));
    }
}
