//! Bytes from an Enttec DMX USB Pro widget: framed by the decoder, each message interpreted as
//! a reply. Must never panic; a message never carries more than MAX_DATA bytes.
#![no_main]

use hitl_drivers::light::enttec::{parse_reply, Decoder, MAX_DATA};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut decoder = Decoder::new();
    for &b in data {
        if let Ok(Some(message)) = decoder.push(b) {
            assert!(message.data.len() <= MAX_DATA);
            let _ = parse_reply(&message);
        }
    }
});
