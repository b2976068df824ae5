"""The peer's connection loop over a socket pair, with a minimal client written here."""
import json
import socket
import struct
import tempfile
import threading
import unittest

import numpy as np

from hitl_foundationpose import peer, wire
from hitl_foundationpose.session import Options, Shared
from tests import helpers

DTYPES = {np.dtype("<f8"): "<f8", np.dtype("<f4"): "<f4", np.dtype("<u4"): "<u4",
          np.dtype("u1"): "u1"}


def send_message(conn, header, arrays=None):
    arrays = arrays or {}
    header = dict(header, payloads=[
        {"name": n, "dtype": DTYPES[a.dtype], "shape": list(a.shape), "bytes": a.nbytes}
        for n, a in arrays.items()])
    body = json.dumps(header).encode()
    conn.sendall(struct.pack("<I", len(body)) + body
                 + b"".join(np.ascontiguousarray(a).tobytes() for a in arrays.values()))


def read_reply(conn):
    header, arrays = wire.read_message(conn)
    assert arrays == {}, "replies carry no payloads"
    return header


def hello(version=1, mesh=True):
    v, f = helpers.box_mesh(0.4)
    arrays = {"vertices": v, "triangles": f.astype("<u4")} if mesh else {}
    return {"type": "hello", "protocol": "hitl-pose", "version": version, "client": "test"}, arrays


class PeerTest(unittest.TestCase):
    def setUp(self):
        self.fp = helpers.stand_in()
        tmp = tempfile.TemporaryDirectory()
        self.addCleanup(tmp.cleanup)
        self.shared = Shared(self.fp)
        self.options = Options(debug_dir=tmp.name)

    def connect(self):
        client, server = socket.socketpair()
        self.addCleanup(client.close)
        errors = []

        def run():
            with server:
                try:
                    peer.serve(server, self.fp, self.shared, self.options, lambda m: None)
                except wire.Closed:
                    pass
                except Exception as e:  # surfaced by the test
                    errors.append(e)

        t = threading.Thread(target=run, daemon=True)
        t.start()

        def finish():
            client.close()
            t.join(5)
            self.assertFalse(t.is_alive())
            self.assertEqual(errors, [])
        self.addCleanup(finish)
        # Only a guard against a peer that never answers: under a loaded CI run (two cores,
        # the Rust suite beside it) the first session's answer took over 10 s.
        client.settimeout(60)
        return client

    def test_another_version_or_no_mesh_is_refused(self):
        c = self.connect()
        send_message(c, *hello(version=2))
        r = read_reply(c)
        self.assertEqual((r["type"], r["accept"], r["version"]), ("hello", False, 1))
        self.assertIn("version 1 only", r["reason"])
        c = self.connect()
        send_message(c, *hello(mesh=False))
        r = read_reply(c)
        self.assertFalse(r["accept"])
        self.assertIn("lacks payload `vertices`", r["reason"])

    def test_a_session_refuses_a_frame_without_a_mask_and_stays_in_step(self):
        c = self.connect()
        send_message(c, *hello())
        r = read_reply(c)
        self.assertTrue(r["accept"])
        self.assertIn("FoundationPose via hitl_foundationpose (mesh 8 vertices 12 triangles",
                      r["estimator"])
        send_message(c, *helpers.frame(3, median_m=4.0, mask=False))
        r = read_reply(c)
        self.assertEqual(r["type"], "error")
        self.assertIn("frame 3 has no target mask", r["reason"])
        header, arrays = helpers.frame(4, median_m=4.0)
        send_message(c, header, arrays)
        r = read_reply(c)
        self.assertEqual((r["type"], r["seq"], r["kind"]), ("pose", 4, "registered"))
        np.testing.assert_allclose(helpers.reply_pose(r)[:3, 3], helpers.true_centroid(arrays),
                                   rtol=1e-6)
        send_message(c, *helpers.frame(5, median_m=4.0))
        self.assertEqual(read_reply(c)["kind"], "tracked")
        send_message(c, {"type": "reset"})
        self.assertEqual(read_reply(c), {"type": "reset"})
        send_message(c, *helpers.frame(6, median_m=4.0))
        self.assertEqual(read_reply(c)["kind"], "registered")
        send_message(c, {"type": "banana"})
        self.assertIn("unknown message type 'banana'", read_reply(c)["reason"])


if __name__ == "__main__":
    unittest.main()
