#!/usr/bin/env python3
"""Read a hitl recording with the official Python `mcap` reader and `mcap-protobuf-support`.

Walks the file record by record (so a file cut short by a crash is read up to its last complete
record), decodes every message (JSON or protobuf), and prints one JSON object:
topics, counts, time ranges, metadata, decoded samples and the values of the first depth image.
Used by hitl-record's interoperability tests.

usage: read_mcap_check.py FILE.mcap [--depth-pixels i,j,k]
"""
import json
import sys

try:
    import numpy as np
    from mcap.records import Channel, Footer, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap_protobuf.decoder import DecoderFactory
except ImportError as e:  # pragma: no cover
    print(json.dumps({"error": f"python peer missing ({e}): run make setup"}))
    sys.exit(3)


def depth_metres(img):
    w, h, step = img.width, img.height, img.step
    raw = bytes(img.data)
    if img.encoding == "32FC1":
        a = np.frombuffer(raw, dtype="<f4", count=(step // 4) * h).reshape(h, step // 4)[:, :w]
        return a.astype(np.float64)
    if img.encoding == "16UC1":
        a = np.frombuffer(raw, dtype="<u2", count=(step // 2) * h).reshape(h, step // 2)[:, :w]
        return a.astype(np.float64) / 1000.0
    raise ValueError(f"not a depth encoding: {img.encoding}")


def main():
    path = sys.argv[1]
    pixels = []
    if "--depth-pixels" in sys.argv:
        pixels = [int(v) for v in sys.argv[sys.argv.index("--depth-pixels") + 1].split(",")]
    schemas, channels = {}, {}
    counts, first, last, encodings = {}, {}, {}, {}
    metadata = {}
    samples = {}
    depth = None
    complete = False
    error = None
    decoders = DecoderFactory()
    decode_cache = {}
    try:
        with open(path, "rb") as f:
            for rec in StreamReader(f, record_size_limit=1 << 30).records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, Metadata):
                    metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Footer):
                    complete = True
                elif isinstance(rec, Message):
                    ch = channels[rec.channel_id]
                    t = ch.topic
                    counts[t] = counts.get(t, 0) + 1
                    first[t] = min(first.get(t, rec.log_time), rec.log_time)
                    last[t] = max(last.get(t, rec.log_time), rec.log_time)
                    sch = schemas.get(ch.schema_id)
                    encodings[t] = [ch.message_encoding, sch.encoding if sch else "", sch.name if sch else ""]
                    if ch.message_encoding == "json":
                        msg = json.loads(rec.data)
                        samples.setdefault(t, msg)
                        samples[t + "#last"] = msg
                    elif ch.message_encoding == "protobuf":
                        if ch.id not in decode_cache:
                            decode_cache[ch.id] = decoders.decoder_for(ch.message_encoding, sch)
                        msg = decode_cache[ch.id](rec.data)
                        if t == "/camera/depth" and depth is None:
                            d = depth_metres(msg)
                            depth = {
                                "encoding": msg.encoding,
                                "width": msg.width,
                                "height": msg.height,
                                "stamp_ns": msg.timestamp.seconds * 10**9 + msg.timestamp.nanos,
                                "log_time": rec.log_time,
                                "sum_m": float(d.sum()),
                                "pixels_m": [float(d.flat[i]) for i in pixels],
                            }
                        elif t in ("/pose/gt", "/pose/estimate") and t not in samples:
                            p = msg.pose
                            samples[t] = {
                                "frame_id": msg.frame_id,
                                "stamp_ns": msg.timestamp.seconds * 10**9 + msg.timestamp.nanos,
                                "position": [p.position.x, p.position.y, p.position.z],
                                "orientation": [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w],
                            }
                        elif t == "/tf" and t not in samples:
                            samples[t] = [[x.parent_frame_id, x.child_frame_id] for x in msg.transforms]
                        elif t == "/camera/calibration" and t not in samples:
                            samples[t] = {"width": msg.width, "height": msg.height, "K": list(msg.K)}
                        elif t in ("/camera/color", "/camera/mask") and t not in samples:
                            samples[t] = {"encoding": msg.encoding, "width": msg.width, "height": msg.height, "bytes": len(msg.data)}
    except Exception as e:  # a crash-cut file ends in a partial record
        error = f"{type(e).__name__}: {e}"
    print(json.dumps({
        "complete": complete,
        "error": error,
        "topics": sorted(ch.topic for ch in channels.values()),
        "counts": counts,
        "first_log_time": first,
        "last_log_time": last,
        "encodings": encodings,
        "metadata": metadata,
        "samples": samples,
        "depth": depth,
    }))


if __name__ == "__main__":
    main()
