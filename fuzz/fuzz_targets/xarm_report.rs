//! Fuzz the xArm report decoders (ports 30000-30003): report framing over a stream cut into
//! arbitrary reads, and decoding of every report kind. None may panic, whatever the bytes.
#![no_main]

use hitl_drivers::xarm::framing::FrameAccumulator;
use hitl_drivers::xarm::report::{decode_report, report_frame_len, ReportKind, MAX_REPORT_LEN};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = report_frame_len(data);
    for kind in ReportKind::ALL {
        if let Ok(r) = decode_report(data, kind) {
            assert!(r.state <= 9 && r.mode <= 11, "out-of-range fields must be errors");
        }
    }
    let Some((&step, stream)) = data.split_first() else { return };
    let step = usize::from(step).max(1);
    let mut acc = FrameAccumulator::<{ 2 * MAX_REPORT_LEN }>::new();
    for chunk in stream.chunks(step) {
        if acc.push(chunk).is_err() {
            return;
        }
        loop {
            match acc.poll_frame(report_frame_len) {
                Ok(Some(_)) => {
                    for kind in ReportKind::ALL {
                        let _ = decode_report(acc.frame(), kind);
                    }
                }
                Ok(None) => break,
                Err(_) => return,
            }
        }
    }
});
