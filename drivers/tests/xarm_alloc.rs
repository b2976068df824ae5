//! The servo hot path allocates nothing: encoding a servo_j into the caller's buffer, the
//! client's pipelined `servo_joint` (drain replies, check state bits, write) and its `stop`
//! (set_state(4) without waiting) against a minimal box on loopback that answers everything.

use hitl_drivers::xarm::codec::{
    decode_request, encode_reply, encode_servo_j, frame_len, Accept, SERVO_J_LEN,
};
use hitl_drivers::xarm::framing::FrameAccumulator;
use hitl_drivers::xarm::{ClientConfig, ServoReplies, XarmClient};
use hitl_hal::Arm;
use std::io::Write;
use std::net::TcpListener;

/// Answers every request with an empty, all-clear reply.
fn tiny_box(listener: TcpListener) {
    let Ok((mut s, _)) = listener.accept() else { return };
    let mut rx = FrameAccumulator::<4096>::new();
    let mut out = [0u8; 64];
    loop {
        match rx.fill_from(&mut s) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        while let Ok(Some(_)) = rx.poll_frame(|b| frame_len(b, Accept::Any)) {
            let Ok(req) = decode_request(rx.frame()) else { return };
            let n = encode_reply(&mut out, req.transaction, req.protocol, req.register, 0, &[])
                .expect("fits");
            if s.write_all(&out[..n]).is_err() {
                return;
            }
        }
    }
}

#[test]
fn servo_j_encoding_allocates_nothing() {
    let mut buf = [0u8; SERVO_J_LEN];
    let q = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];
    let info = allocation_counter::measure(|| {
        for t in 0..1000u16 {
            encode_servo_j(&mut buf, t, &q);
        }
    });
    assert_eq!(info.count_total, 0);
}

#[test]
fn pipelined_servo_joint_allocates_nothing() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("binds");
    let addr = listener.local_addr().expect("addr");
    let server = std::thread::spawn(move || tiny_box(listener));
    // Backlog limits are not the point here: allow many replies in flight on a loaded machine.
    let config = ClientConfig {
        servo_replies: ServoReplies::Pipelined { max_outstanding: 100_000 },
        ..ClientConfig::default()
    };
    let mut arm = XarmClient::connect(addr, config).expect("connects");
    let mut q = [0.0; 7];
    // Warm up (first socket reads, lazily initialised state).
    for _ in 0..10 {
        arm.servo_joint(&q).expect("servo_j");
    }
    arm.flush_servo_replies().expect("replies");
    let info = allocation_counter::measure(|| {
        for i in 0..500 {
            q[0] = f64::from(i) * 1e-4;
            arm.servo_joint(&q).expect("servo_j");
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
    });
    arm.flush_servo_replies().expect("replies");
    assert_eq!(arm.servo_sent(), 510);
    assert_eq!(info.count_total, 0, "hot path allocated {} times", info.count_total);
    let info = allocation_counter::measure(|| {
        for _ in 0..30 {
            arm.stop().expect("stop written");
        }
    });
    assert_eq!(info.count_total, 0, "stop allocated {} times", info.count_total);
    arm.flush_servo_replies().expect("the stops' replies");
    assert_eq!(arm.outstanding(), 0);
    arm.shutdown();
    server.join().expect("box thread");
}
