//! The Orbbec SDK double for tests through the `hitl` binary: `fake_orbbec.c` (a stand-in for
//! libOrbbecSDK.so with the symbols the driver resolves, described at its top) is compiled with
//! the system's C compiler into a fresh folder, which also holds the fake cameras' state, and
//! `hitl` is pointed at it with `HITL_ORBBEC_LIB`; hitl's state files go to a folder of their own
//! (`HITL_STATE_DIR`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

pub struct FakeOrbbec {
    pub dir: tempfile::TempDir,
    pub lib: PathBuf,
    pub state: PathBuf,
}

/// The sync configuration a fake camera has out of the box: free-run, trigger out on.
pub const FACTORY_SYNC: &str = "1 0 0 0 1 0 1";

impl FakeOrbbec {
    /// A fake SDK with these cameras connected: (serial, product id, firmware).
    pub fn new(cameras: &[(&str, u16, &str)]) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/orbbec_fake/fake_orbbec.c");
        let lib = dir.path().join("libOrbbecSDK.so");
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let out = Command::new(&cc)
            .args(["-shared", "-fPIC", "-O1", "-o"])
            .arg(&lib)
            .arg(&src)
            .output()
            .unwrap_or_else(|e| panic!("the fake Orbbec SDK needs a C compiler ({cc}): {e}"));
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let list: String = cameras
            .iter()
            .map(|(sn, pid, fw)| format!("{sn} {pid:x} {fw} Orbbec Gemini 305 (fake)\n"))
            .collect();
        std::fs::write(dir.path().join("cameras"), list).expect("cameras");
        let state = dir.path().join("hitl-state");
        Self { dir, lib, state }
    }

    /// `hitl ARGS` against this fake SDK.
    pub fn hitl(&self) -> Command {
        let mut c = Command::new(env!("CARGO_BIN_EXE_hitl"));
        c.env("HITL_ORBBEC_LIB", &self.lib)
            .env("HITL_FAKE_ORBBEC_DIR", self.dir.path())
            .env("HITL_STATE_DIR", &self.state);
        c
    }

    /// The camera's sync configuration now: "mode depth colour trigger2image out out_delay
    /// frames" (the factory's until something wrote one).
    pub fn sync(&self, serial: &str) -> String {
        std::fs::read_to_string(self.dir.path().join(format!("{serial}.sync")))
            .map(|s| s.trim().to_string())
            .unwrap_or_else(|_| FACTORY_SYNC.into())
    }

    /// Set the camera's sync configuration, as another tool or a crashed run would leave it.
    pub fn set_sync(&self, serial: &str, sync: &str) {
        std::fs::write(self.dir.path().join(format!("{serial}.sync")), sync).expect("sync");
    }

    /// hitl's state file for the camera (present while hitl has the camera changed).
    pub fn marker(&self, serial: &str) -> PathBuf {
        self.state.join("orbbec").join(format!("{serial}.sync"))
    }

    /// The calls that changed something, one a line.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("log")).unwrap_or_default()
    }

    /// Offer only these stream sizes (every stream, RGB/Y16 at 30 and 15 fps).
    pub fn sizes(&self, sizes: &[(u32, u32)]) {
        let text: String = sizes.iter().map(|(w, h)| format!("{w} {h}\n")).collect();
        std::fs::write(self.dir.path().join("sizes"), text).expect("sizes");
    }

    /// A FIFO: each 8 bytes written (a CLOCK_MONOTONIC time in us, little-endian) are one pulse
    /// on the cameras' sync inputs, exposed then.
    pub fn pulses(&self) -> PathBuf {
        let path = self.dir.path().join("pulses");
        if !path.exists() {
            nix::unistd::mkfifo(&path, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
        }
        path
    }
}
