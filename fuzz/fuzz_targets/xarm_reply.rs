//! Fuzz the xArm command-socket decoders: framing of a reply stream cut into arbitrary reads,
//! reply and request decoding, and the payload readers. None may panic, whatever the bytes.
#![no_main]

use hitl_drivers::xarm::codec::{
    decode_codes, decode_joints, decode_reply, decode_request, frame_len, Accept, CodecError,
};
use hitl_drivers::xarm::framing::FrameAccumulator;
use libfuzzer_sys::fuzz_target;

fn private(buf: &[u8]) -> Result<Option<usize>, CodecError> {
    frame_len(buf, Accept::Private)
}

fuzz_target!(|data: &[u8]| {
    let _ = decode_request(data);
    let _ = frame_len(data, Accept::Any);
    if let Ok(r) = decode_reply(data) {
        let _ = decode_joints(&r);
        let _ = decode_codes(&r);
    }
    // The first byte sets the read size, the rest is the stream.
    let Some((&step, stream)) = data.split_first() else { return };
    let step = usize::from(step).max(1);
    let mut acc = FrameAccumulator::<4096>::new();
    for chunk in stream.chunks(step) {
        if acc.push(chunk).is_err() {
            return;
        }
        loop {
            match acc.poll_frame(private) {
                Ok(Some(n)) => {
                    assert_eq!(acc.frame().len(), n);
                    let _ = decode_reply(acc.frame());
                }
                Ok(None) => break,
                Err(_) => return,
            }
        }
        assert!(acc.pending() <= 4096);
    }
});
