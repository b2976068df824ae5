//! The command port: accepts connections, cuts each byte stream into request frames, answers
//! each through the box no faster than a box does (every frame takes a slot of the shared
//! [`CommandPacer`](super::CommandPacer): 250 per second, so a faster stream backs up in the
//! socket as on a real box), and closes a connection on garbage, on shutdown or on a
//! drop-connection fault. A stall-replies fault stops reading (and so answering) without closing.

use super::{Shared, POLL};
use hitl_drivers::xarm::codec::{
    decode_request, encode_reply, frame_len, Accept, CodecError, PROTOCOL_HEARTBEAT,
    PROTOCOL_STANDARD,
};
use hitl_drivers::xarm::framing::FrameAccumulator;
use std::io::{self, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::Ordering;
use std::sync::Arc;

const RX_CAP: usize = 8192;

fn any_frame_len(buf: &[u8]) -> Result<Option<usize>, CodecError> {
    frame_len(buf, Accept::Any)
}

/// Accept loop of the command port.
pub fn serve(shared: Arc<Shared>, listener: TcpListener) {
    let mut workers = Vec::new();
    while !shared.stopping() {
        match listener.accept() {
            Ok((stream, _)) => {
                shared.counters.connections.fetch_add(1, Ordering::Relaxed);
                let s = shared.clone();
                if let Ok(t) =
                    shared.thread_start.spawn("hitl-stub-cmd-conn", move || connection(s, stream))
                {
                    workers.push(t);
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => std::thread::sleep(POLL / 4),
            Err(_) => std::thread::sleep(POLL),
        }
        workers.retain(|t| !t.is_finished());
    }
    for t in workers {
        let _ = t.join();
    }
}

fn connection(shared: Arc<Shared>, stream: TcpStream) {
    // On a simulated clock the host counts the open command connections: with none, nothing it
    // writes will be answered, and it does not wait for answers.
    if let Some(sim) = &shared.sim {
        sim.command_connections.fetch_add(1, Ordering::AcqRel);
    }
    serve_connection(&shared, stream);
    if let Some(sim) = &shared.sim {
        sim.command_connections.fetch_sub(1, Ordering::AcqRel);
    }
}

fn serve_connection(shared: &Shared, mut stream: TcpStream) {
    let epoch = shared.drop_epoch.load(Ordering::SeqCst);
    if stream.set_nodelay(true).is_err() || stream.set_read_timeout(Some(POLL)).is_err() {
        return;
    }
    let _ = stream.set_write_timeout(Some(std::time::Duration::from_secs(2)));
    let mut rx = Box::new(FrameAccumulator::<RX_CAP>::new());
    let mut out = [0u8; 1024];
    loop {
        if shared.stopping() || shared.drop_epoch.load(Ordering::SeqCst) != epoch {
            break;
        }
        if shared.replies_stalled() {
            // A box that hears nothing: requests wait in the socket, or in `rx` if a read
            // was under way when the stall began, unanswered.
            std::thread::sleep(POLL / 4);
            continue;
        }
        // Answer only here, after the stall check: bytes that a read blocked since before the
        // stall brings in are held until the stall ends, never answered during it.
        match answer_all(shared, &mut rx, &mut stream, &mut out) {
            Ok(()) => {}
            Err(ConnError::Codec) => {
                shared.counters.bad_frames.fetch_add(1, Ordering::Relaxed);
                break;
            }
            Err(ConnError::Io) => break,
        }
        match rx.fill_from(&mut stream) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {
                continue
            }
            Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                shared.counters.bad_frames.fetch_add(1, Ordering::Relaxed);
                break;
            }
            Err(_) => break,
        }
    }
    let _ = stream.shutdown(std::net::Shutdown::Both);
}

/// Why a connection ends: bad bytes from the client, or the socket failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ConnError {
    Codec,
    Io,
}

impl From<CodecError> for ConnError {
    fn from(_: CodecError) -> Self {
        ConnError::Codec
    }
}

impl From<io::Error> for ConnError {
    fn from(_: io::Error) -> Self {
        ConnError::Io
    }
}

/// Answer every complete request in the buffer, up to a stall that begins meanwhile.
fn answer_all(
    shared: &Shared,
    rx: &mut FrameAccumulator<RX_CAP>,
    stream: &mut TcpStream,
    out: &mut [u8],
) -> Result<(), ConnError> {
    while !shared.replies_stalled() && rx.poll_frame(any_frame_len)?.is_some() {
        let req = decode_request(rx.frame())?;
        let now_s = shared.pace_command();
        let n = match req.protocol {
            // The SDK's keep-alive frames need no answer.
            PROTOCOL_HEARTBEAT => {
                answered(shared);
                continue;
            }
            // Standard Modbus-TCP (the box's register map) is not simulated: exception 01.
            PROTOCOL_STANDARD => {
                // Standard exception reply: unit id, function | 0x80, exception code 01.
                let fc = req.params.first().copied().unwrap_or(0);
                out[..2].copy_from_slice(&req.transaction.to_be_bytes());
                out[2..9].copy_from_slice(&[0, 0, 0, 3, req.register, fc | 0x80, 0x01]);
                9
            }
            _ => {
                let reply = shared.lock_arm().handle(req.register, req.params, now_s);
                encode_reply(
                    out,
                    req.transaction,
                    req.protocol,
                    req.register,
                    reply.state,
                    reply.data(),
                )?
            }
        };
        stream.write_all(&out[..n])?;
        answered(shared);
    }
    Ok(())
}

/// On a simulated clock: one more request answered (the host waits on the count).
fn answered(shared: &Shared) {
    if let Some(sim) = &shared.sim {
        sim.commands_answered.fetch_add(1, Ordering::AcqRel);
    }
}
