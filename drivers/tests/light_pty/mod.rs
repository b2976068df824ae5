//! Pseudo-terminal peers for the serial driver tests: the test holds the master end and plays the
//! device; the driver opens the slave's path like a USB serial adapter.

#![allow(dead_code)]

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::time::{Duration, Instant};

use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use nix::unistd::ttyname;

/// The device side of a pty pair.
pub struct PtyPeer {
    master: File,
    /// Kept open so the slave exists before and after the driver opens it.
    _slave: OwnedFd,
    pub path: String,
}

impl PtyPeer {
    pub fn new() -> Self {
        let pty = openpty(None, None).expect("openpty");
        let mut t = tcgetattr(&pty.slave).expect("tcgetattr");
        cfmakeraw(&mut t);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &t).expect("tcsetattr");
        let path = ttyname(pty.slave.as_fd()).expect("ttyname").to_string_lossy().into_owned();
        Self { master: File::from(pty.master), _slave: pty.slave, path }
    }

    /// Whether bytes can be read within `timeout`.
    fn readable(&self, timeout: Duration) -> bool {
        let ms = u16::try_from(timeout.as_millis()).unwrap_or(u16::MAX);
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        matches!(poll(&mut fds, PollTimeout::from(ms)), Ok(n) if n > 0)
            && fds[0].revents().is_some_and(|r| r.contains(PollFlags::POLLIN))
    }

    /// Read what arrives within `timeout` (returns early once at least `want` bytes arrived).
    pub fn read_some(&mut self, want: usize, timeout: Duration) -> Vec<u8> {
        let deadline = Instant::now() + timeout;
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        while out.len() < want {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() || !self.readable(left.min(Duration::from_millis(20))) {
                if left.is_zero() {
                    break;
                }
                continue;
            }
            match self.master.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => out.extend_from_slice(&buf[..n]),
            }
        }
        out
    }

    pub fn write(&mut self, bytes: &[u8]) {
        self.master.write_all(bytes).expect("write to pty master");
    }

    /// Try to read without waiting.
    pub fn try_read(&mut self, buf: &mut [u8]) -> usize {
        if self.readable(Duration::from_millis(1)) {
            self.master.read(buf).unwrap_or(0)
        } else {
            0
        }
    }
}

impl Default for PtyPeer {
    fn default() -> Self {
        Self::new()
    }
}

/// Poll `f` every few milliseconds until it returns `Some`, or give up after `timeout`.
pub async fn eventually<T>(timeout: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = f() {
            return Some(v);
        }
        if Instant::now() >= deadline {
            return None;
        }
        tokio::time::sleep(Duration::from_millis(3)).await;
    }
}
