"""The bytes of hitl's external-estimator protocol `hitl-pose` version 1, peer side.

Every message is a u32 little-endian header length, that many bytes of a UTF-8 JSON object with a
string `type`, then the binary payloads its `payloads` list announces, back to back. The protocol
is specified in hitl's docs/perception.md ("External estimator over a socket"); this module only
moves and checks bytes and knows nothing of FoundationPose. numpy only.
"""
import json
import struct

import numpy as np

PROTOCOL = "hitl-pose"
VERSION = 1
MAX_HEADER_BYTES = 1 << 20
# A 1280x1024 frame with colour and mask is 10.5 MB; a 5 M-triangle mesh about 180 MB.
MAX_PAYLOAD_BYTES = 1 << 30
ITEM_BYTES = {"<f8": 8, "<f4": 4, "<u4": 4, "u1": 1}


class Closed(Exception):
    """The client closed the connection (an empty message means: at a message boundary)."""


class ProtocolError(Exception):
    """The client's bytes break the protocol; the stream is out of step."""


def recv_exact(conn, n, at_boundary=False):
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        k = conn.recv_into(view[got:])
        if k == 0:
            if at_boundary and got == 0:
                raise Closed()
            raise Closed("connection closed after {} of {} bytes".format(got, n))
        got += k
    return bytes(buf)


def read_message(conn):
    """One message: (header dict, {payload name: read-only numpy array})."""
    (length,) = struct.unpack("<I", recv_exact(conn, 4, at_boundary=True))
    if length == 0 or length > MAX_HEADER_BYTES:
        raise ProtocolError("header length {} is not in 1..{}".format(length, MAX_HEADER_BYTES))
    try:
        header = json.loads(recv_exact(conn, length).decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ProtocolError("header is not UTF-8 JSON: {}".format(e))
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
            raise ProtocolError("bad payload description {!r}".format(d))
        if d["bytes"] != int(np.prod(d["shape"], dtype=np.int64)) * ITEM_BYTES[d["dtype"]]:
            raise ProtocolError("payload {}: bytes do not match dtype and shape".format(d["name"]))
        total += d["bytes"]
    if total > MAX_PAYLOAD_BYTES:
        raise ProtocolError("payloads of {} bytes exceed {}".format(total, MAX_PAYLOAD_BYTES))
    arrays = {}
    for d in descs:
        raw = recv_exact(conn, d["bytes"])
        arrays[d["name"]] = np.frombuffer(raw, dtype=d["dtype"]).reshape(d["shape"])
    return header, arrays


def send(conn, header):
    """Sends a reply (replies carry no payloads in version 1). JSON has no NaN: refuse it here."""
    body = json.dumps(header, allow_nan=False).encode("utf-8")
    conn.sendall(struct.pack("<I", len(body)) + body)


def error(reason):
    return {"type": "error", "reason": reason}


def hello_reply(accept, estimator=None, reason=None):
    reply = {"type": "hello", "protocol": PROTOCOL, "version": VERSION, "accept": accept}
    if accept:
        reply["estimator"] = estimator
    else:
        reply["reason"] = reason
    return reply


def check_mesh(arrays):
    """(vertices [V,3] f64, triangles [F,3] int64) from a `hello`'s payloads, or raises
    ProtocolError naming the problem."""
    v, f = arrays.get("vertices"), arrays.get("triangles")
    if v is None or f is None:
        raise ProtocolError("hello lacks payload `vertices` or `triangles`")
    if v.dtype != np.dtype("<f8") or v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ProtocolError("`vertices` must be <f8 [V,3], V > 0")
    if f.dtype != np.dtype("<u4") or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise ProtocolError("`triangles` must be <u4 [F,3], F > 0")
    if int(f.max()) >= len(v):
        raise ProtocolError("a triangle indexes a vertex beyond the vertices")
    if not np.isfinite(v).all():
        raise ProtocolError("a vertex is not finite")
    return np.array(v, dtype=np.float64), np.array(f, dtype=np.int64)
