#!/usr/bin/env python3
"""Reference peer of hitl's external-estimator protocol `hitl-pose` version 1.

Listens on a Unix domain socket and answers `hitl run --perception socket:PATH` or
`hitl eval RUN.mcap --backend socket:PATH`. The protocol is specified in docs/perception.md
("External estimator over a socket"); this script is its executable reference and the peer of
perception/tests/socket.rs. It needs numpy only.

The estimate is deliberately simple: a translation-only pose whose translation is the centroid of
the target pixels (mask != 0 if the frame has a mask, and depth finite and > 0) back-projected
with the frame's intrinsics (x = (u - cx) / fx * z, y = (v - cy) / fy * z, pixel centres at
integer coordinates), identity rotation, kind "direct"; lost (pose null) when no pixel qualifies.
The mesh from the handshake is checked and summarised in the peer's name, not used.

The socket appears only once it is listening (bound under a temporary name, then renamed), so a
client may connect as soon as PATH exists. One connection is served at a time; the peer runs
until killed (SIGTERM or SIGINT remove the socket).

Faults (--fault) make the peer misbehave so the client's error paths can be tested:
  refuse        refuse the hello (accept false, with a reason)
  bad-hello     accept the hello claiming protocol version 99
  garbage       answer a frame with a header that is not JSON
  close         close the connection on receiving a frame, without a reply
  truncated     send a reply length of 100 bytes, then 10 bytes, then close
  wrong-seq     answer a frame with seq + 1
  slow          sleep --delay seconds before answering a frame
  huge-length   announce a reply header of 0xFFFFFFF0 bytes
  non-rigid     answer with a finite pose whose rotation block is scaled by 2
  nan           answer with NaN in the pose (JSON has no NaN: Python writes a bare NaN)
  short-pose    answer with 15 pose numbers
  missing-field answer without the `pose` field
  extra-field   answer with an extra field `banana`
  error         answer a frame with an `error` reply (the connection stays in step)
  reset-close   close the connection on receiving a reset
Frame faults fire on frames, reset-close on resets, refuse and bad-hello on handshakes; each
fires on the first --fault-count opportunities (default: all), then the peer behaves.
"""
import argparse
import json
import os
import signal
import socket
import struct
import sys
import time

import numpy as np

PROTOCOL = "hitl-pose"
VERSION = 1
MAX_HEADER_BYTES = 1 << 20
MAX_PAYLOAD_BYTES = 1 << 30
ITEM_BYTES = {"<f8": 8, "<f4": 4, "<u4": 4, "u1": 1}
FAULTS = [
    "refuse", "bad-hello", "garbage", "close", "truncated", "wrong-seq", "slow", "huge-length",
    "non-rigid", "nan", "short-pose", "missing-field", "extra-field", "error", "reset-close",
]
FRAME_FAULTS = set(FAULTS) - {"refuse", "bad-hello", "reset-close"}


class Closed(Exception):
    """The client closed the connection."""


class ProtocolError(Exception):
    """The client broke the protocol: answered with an `error` reply."""


def recv_exact(conn, n, at_boundary=False):
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        k = conn.recv_into(view[got:])
        if k == 0:
            if at_boundary and got == 0:
                raise Closed()
            raise Closed(f"connection closed after {got} of {n} bytes")
        got += k
    return bytes(buf)


def read_message(conn):
    """One message: (header dict, {payload name: numpy array}). Raises Closed at end of stream."""
    (length,) = struct.unpack("<I", recv_exact(conn, 4, at_boundary=True))
    if length == 0 or length > MAX_HEADER_BYTES:
        raise ProtocolError(f"header length {length} is not in 1..{MAX_HEADER_BYTES}")
    try:
        header = json.loads(recv_exact(conn, length).decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ProtocolError(f"header is not UTF-8 JSON: {e}")
    if not isinstance(header, dict) or not isinstance(header.get("type"), str):
        raise ProtocolError("header is not an object with a string `type`")
    descs = header.get("payloads", [])
    if not isinstance(descs, list):
        raise ProtocolError("`payloads` is not a list")
    total = 0
    for d in descs:
        ok = (isinstance(d, dict) and isinstance(d.get("name"), str)
              and d.get("dtype") in ITEM_BYTES and isinstance(d.get("shape"), list)
              and all(isinstance(s, int) and s >= 0 for s in d["shape"])
              and isinstance(d.get("bytes"), int))
        if not ok:
            raise ProtocolError(f"bad payload description {d!r}")
        if d["bytes"] != int(np.prod(d["shape"], dtype=np.int64)) * ITEM_BYTES[d["dtype"]]:
            raise ProtocolError(f"payload {d['name']}: bytes do not match dtype and shape")
        total += d["bytes"]
    if total > MAX_PAYLOAD_BYTES:
        raise ProtocolError(f"payloads of {total} bytes exceed {MAX_PAYLOAD_BYTES}")
    arrays = {}
    for d in descs:
        raw = recv_exact(conn, d["bytes"])
        arrays[d["name"]] = np.frombuffer(raw, dtype=d["dtype"]).reshape(d["shape"])
    return header, arrays


def send(conn, header):
    body = json.dumps(header).encode("utf-8")  # allow_nan: the `nan` fault needs it
    conn.sendall(struct.pack("<I", len(body)) + body)


def send_raw_header(conn, body):
    conn.sendall(struct.pack("<I", len(body)) + body)


def check_mesh(arrays):
    v, f = arrays.get("vertices"), arrays.get("triangles")
    if v is None or f is None:
        return None, "hello lacks payload `vertices` or `triangles`"
    if v.dtype != np.dtype("<f8") or v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        return None, "`vertices` must be <f8 [V,3], V > 0"
    if f.dtype != np.dtype("<u4") or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        return None, "`triangles` must be <u4 [F,3], F > 0"
    if int(f.max()) >= len(v):
        return None, "a triangle indexes a vertex beyond the vertices"
    if not np.isfinite(v).all():
        return None, "a vertex is not finite"
    return (v, f), None


def centroid_pose(header, arrays):
    """Translation-only pose at the centroid of the back-projected target pixels, or None."""
    k = header["intrinsics"]
    h, w = int(k["height"]), int(k["width"])
    depth = arrays.get("depth")
    if depth is None or depth.shape != (h, w) or depth.dtype != np.dtype("<f4"):
        raise ProtocolError("frame lacks payload `depth` <f4 [height,width]")
    z = depth.astype(np.float64)
    target = np.isfinite(z) & (z > 0)
    mask = arrays.get("mask")
    if mask is not None:
        if mask.shape != (h, w):
            raise ProtocolError("`mask` is not [height,width]")
        target &= mask != 0
    color = arrays.get("color")
    if color is not None and color.shape != (h, w, 3):
        raise ProtocolError("`color` is not [height,width,3]")
    if not target.any():
        return None
    v, u = np.nonzero(target)
    zs = z[v, u]
    xs = (u - float(k["cx"])) / float(k["fx"]) * zs
    ys = (v - float(k["cy"])) / float(k["fy"]) * zs
    pose = np.eye(4)
    pose[:3, 3] = [xs.mean(), ys.mean(), zs.mean()]
    return pose


class Faults:
    def __init__(self, fault, count):
        self.fault, self.left = fault, count

    def fires(self, fault):
        if self.fault != fault or self.left == 0:
            return False
        self.left -= 1
        return True

    def frame_fault(self):
        if self.fault in FRAME_FAULTS and self.fires(self.fault):
            return self.fault
        return None


def frame_reply(header, arrays, args, since_reset, fault):
    seq = header.get("seq")
    if not isinstance(seq, int) or "intrinsics" not in header:
        raise ProtocolError("frame lacks `seq` or `intrinsics`")
    pose = centroid_pose(header, arrays)
    reply = {"type": "pose", "seq": seq, "pose": None}
    if pose is not None:
        if fault == "non-rigid":
            pose[:3, :3] *= 2.0
        elif fault == "nan":
            pose[0, 3] = float("nan")
        reply["pose"] = [float(x) for x in pose.reshape(-1)]
        if fault == "short-pose":
            reply["pose"] = reply["pose"][:15]
        kind = args.kind
        if kind == "auto":
            kind = "registered" if since_reset == 0 else "tracked"
        reply["kind"] = kind
        if args.residual is not None:
            reply["residual_m"] = args.residual
    if fault == "wrong-seq":
        reply["seq"] = seq + 1
    elif fault == "missing-field":
        del reply["pose"]
    elif fault == "extra-field":
        reply["banana"] = 1
    return reply


def serve(conn, args, faults, log):
    """One connection. Returns when the client closes it or a fault closes it."""
    header, arrays = read_message(conn)
    if header["type"] != "hello":
        send(conn, {"type": "error", "reason": "the first message must be `hello`"})
        return
    if header.get("protocol") != PROTOCOL or header.get("version") != VERSION:
        send(conn, {"type": "hello", "protocol": PROTOCOL, "version": VERSION, "accept": False,
                    "reason": f"this peer speaks {PROTOCOL} version {VERSION} only"})
        return
    mesh, problem = check_mesh(arrays)
    if problem is None and faults.fires("refuse"):
        problem = "refused by --fault refuse"
    if problem is not None:
        send(conn, {"type": "hello", "protocol": PROTOCOL, "version": VERSION, "accept": False,
                    "reason": problem})
        return
    v, f = mesh
    size = float((v.max(axis=0) - v.min(axis=0)).max())
    name = f"pose_peer centroid (mesh {len(v)} vertices {len(f)} triangles size {size!r} m)"
    version = 99 if faults.fires("bad-hello") else VERSION
    send(conn, {"type": "hello", "protocol": PROTOCOL, "version": version, "accept": True,
                "estimator": name})
    log(f"accepted {header.get('client')!r}: {len(v)} vertices, {len(f)} triangles")
    since_reset = 0
    while True:
        try:
            header, arrays = read_message(conn)
        except ProtocolError as e:
            send(conn, {"type": "error", "reason": str(e)})
            return  # the stream is out of step: end the connection
        kind = header["type"]
        if kind == "reset":
            if faults.fires("reset-close"):
                return
            since_reset = 0
            send(conn, {"type": "reset"})
        elif kind == "frame":
            fault = faults.frame_fault()
            if fault == "close":
                return
            if fault == "truncated":
                conn.sendall(struct.pack("<I", 100) + b'{"type": "')
                return
            if fault == "huge-length":
                conn.sendall(struct.pack("<I", 0xFFFFFFF0) + b"{}")
                return
            if fault == "garbage":
                send_raw_header(conn, b"this is not json")
                continue
            if fault == "error":
                send(conn, {"type": "error", "reason": "simulated failure (--fault error)"})
                continue
            if fault == "slow":
                time.sleep(args.delay)
            try:
                reply = frame_reply(header, arrays, args, since_reset, fault)
            except ProtocolError as e:
                send(conn, {"type": "error", "reason": str(e)})
                continue
            send(conn, reply)
            since_reset += 1
        else:
            send(conn, {"type": "error", "reason": f"unknown message type {kind!r}"})


def main():
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("socket", help="path of the Unix socket to listen on (replaced if it exists)")
    p.add_argument("--kind", default="direct", choices=["direct", "registered", "tracked", "auto"],
                   help="kind reported with a pose; auto: registered on the first frame of a "
                        "connection or after a reset, tracked after that (default: direct)")
    p.add_argument("--residual", type=float, default=None,
                   help="residual_m reported with a pose (default: none)")
    p.add_argument("--fault", choices=FAULTS, default=None, help="misbehave (see above)")
    p.add_argument("--fault-count", type=int, default=-1,
                   help="how many times the fault fires (default: every time)")
    p.add_argument("--delay", type=float, default=5.0, help="seconds of the `slow` fault")
    p.add_argument("--quiet", action="store_true", help="no log on stderr")
    args = p.parse_args()

    def log(msg):
        if not args.quiet:
            print(f"pose_peer: {msg}", file=sys.stderr, flush=True)

    path = args.socket
    tmp = f"{path}.{os.getpid()}.tmp"
    for old in (path, tmp):
        if os.path.lexists(old):
            os.unlink(old)
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(tmp)
    server.listen(4)
    os.rename(tmp, path)  # PATH exists only once it is listening

    def stop(signum, _frame):
        if os.path.lexists(path):
            os.unlink(path)
        sys.exit(0)

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    log(f"listening on {path}")
    faults = Faults(args.fault, args.fault_count)
    while True:
        conn, _ = server.accept()
        with conn:
            try:
                serve(conn, args, faults, log)
            except Closed as e:
                if str(e):
                    log(f"client: {e}")
            except ProtocolError as e:
                log(f"client broke the protocol: {e}")
            except OSError as e:
                log(f"connection failed: {e}")
        log("connection ended")


if __name__ == "__main__":
    main()
