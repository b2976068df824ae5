//! Property tests: the xArm decoders and the frame accumulator never panic on arbitrary bytes,
//! never hold more than their capacity, and cut valid streams into the frames that were sent,
//! however the stream is split into reads.

use hitl_drivers::xarm::codec::{
    decode_reply, decode_request, encode_reply, encode_servo_j, frame_len, Accept, SERVO_J_LEN,
};
use hitl_drivers::xarm::framing::FrameAccumulator;
use hitl_drivers::xarm::report::{decode_report, report_frame_len, ReportKind};
use proptest::prelude::*;

fn cmd_len(buf: &[u8]) -> Result<Option<usize>, hitl_drivers::xarm::codec::CodecError> {
    frame_len(buf, Accept::Private)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn decoders_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..1200)) {
        let _ = decode_reply(&bytes);
        let _ = decode_request(&bytes);
        let _ = frame_len(&bytes, Accept::Any);
        let _ = report_frame_len(&bytes);
        for kind in ReportKind::ALL {
            let _ = decode_report(&bytes, kind);
        }
    }

    #[test]
    fn report_decoder_never_panics_on_plausible_sizes(
        size in 0usize..1100, fill in any::<u8>(), kind in 0usize..4,
    ) {
        let mut bytes = vec![fill; size.max(4)];
        bytes[..4].copy_from_slice(&(size as u32).to_be_bytes());
        let _ = decode_report(&bytes, ReportKind::ALL[kind]);
    }

    #[test]
    fn accumulator_survives_garbage(chunks in proptest::collection::vec(
        proptest::collection::vec(any::<u8>(), 0..300), 0..20)) {
        let mut acc = FrameAccumulator::<512>::new();
        for chunk in &chunks {
            if acc.push(chunk).is_err() {
                acc.clear();
                continue;
            }
            loop {
                match acc.poll_frame(cmd_len) {
                    Ok(Some(n)) => {
                        prop_assert_eq!(acc.frame().len(), n);
                        let _ = decode_reply(acc.frame());
                    }
                    Ok(None) => break,
                    Err(_) => { acc.clear(); break; }
                }
            }
            prop_assert!(acc.pending() <= 512);
        }
    }

    #[test]
    fn valid_stream_split_anywhere_yields_the_frames(
        joints in proptest::collection::vec(-6.0f64..6.0, 7),
        n_frames in 1usize..12,
        cuts in proptest::collection::vec(1usize..60, 1..40),
    ) {
        let q: [f64; 7] = [joints[0], joints[1], joints[2], joints[3], joints[4], joints[5], joints[6]];
        let mut stream = Vec::new();
        for t in 0..n_frames {
            if t % 2 == 0 {
                let mut b = [0u8; SERVO_J_LEN];
                encode_servo_j(&mut b, t as u16, &q);
                // Servo requests re-framed as replies' neighbours: a reply carrying the joints.
                let mut r = [0u8; 64];
                let n = encode_reply(&mut r, t as u16, 2, 42, 0, &b[7..35]).expect("fits");
                stream.extend_from_slice(&r[..n]);
            } else {
                let mut r = [0u8; 16];
                let n = encode_reply(&mut r, t as u16, 2, 15, 0x40, &[23, 0]).expect("fits");
                stream.extend_from_slice(&r[..n]);
            }
        }
        let mut acc = FrameAccumulator::<256>::new();
        let mut got = Vec::new();
        let mut at = 0;
        let mut cut = cuts.iter().cycle();
        while at < stream.len() {
            let end = (at + cut.next().copied().unwrap_or(7)).min(stream.len());
            acc.push(&stream[at..end]).expect("fits");
            at = end;
            while let Some(_n) = acc.poll_frame(cmd_len).expect("valid stream") {
                let r = decode_reply(acc.frame()).expect("valid reply");
                got.push(r.transaction);
                if r.register == 42 {
                    let mut back = [0.0; 7];
                    hitl_drivers::xarm::codec::read_f32s(r.data, 42, &mut back).expect("7 floats");
                    for j in 0..7 {
                        prop_assert!((back[j] - q[j]).abs() < 1e-5);
                    }
                } else {
                    prop_assert_eq!(r.data, &[23u8, 0][..]);
                    prop_assert!(r.state.error());
                }
            }
        }
        prop_assert_eq!(got, (0..n_frames as u16).collect::<Vec<_>>());
    }
}
