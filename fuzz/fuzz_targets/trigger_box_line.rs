//! Bytes from the trigger box: split into lines by the bounded line buffer, each line parsed.
//! Must never panic; no line handed out is longer than the protocol's 64 bytes.
#![no_main]

use hitl_drivers::light::protocol::{parse_line, LineBuffer, Pushed, MAX_LINE};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = parse_line(data);
    let mut lines = LineBuffer::new();
    for &b in data {
        if let Pushed::Line(l) = lines.push(b) {
            assert!(l.len() < MAX_LINE);
            let _ = parse_line(l);
            lines.clear();
        }
    }
});
