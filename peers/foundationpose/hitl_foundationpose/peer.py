"""Serves NVIDIA FoundationPose to hitl over protocol `hitl-pose` version 1 on a Unix socket.

    python -m hitl_foundationpose SOCKET --foundationpose-dir DIR

DIR is a FoundationPose checkout with its extensions built and its weights under DIR/weights
(see README.md). At start the peer imports DIR's `estimater` module and builds the scorer, the
refiner and the CUDA rasteriser context once; only then does SOCKET appear (bound under a
temporary name, then renamed), so hitl may connect as soon as it exists. Each connection hands
over the target mesh in its `hello` and gets its own FoundationPose estimator built on those
shared networks ([`session`] says what a frame does). One connection at a time; the peer runs
until SIGTERM or SIGINT, which remove the socket.
"""
import argparse
import importlib
import os
import signal
import socket
import sys
import tempfile
import traceback

from . import wire
from .session import FrameRefused, Options, Session, Shared, stderr_log

WEIGHTS = ("2023-10-28-18-33-37", "2024-01-11-20-02-45")  # refiner, scorer (FoundationPose's)


def load_foundationpose(directory):
    """Imports `estimater` from a FoundationPose checkout (its modules import each other by
    top-level name, as its run_demo.py does from the checkout's root)."""
    directory = os.path.abspath(directory)
    if not os.path.isfile(os.path.join(directory, "estimater.py")):
        raise SystemExit("hitl_foundationpose: {} has no estimater.py: give the FoundationPose "
                         "checkout with --foundationpose-dir".format(directory))
    if directory not in sys.path:
        sys.path.insert(0, directory)
    return importlib.import_module("estimater")


def build_shared(fp, directory):
    try:
        return Shared(fp)
    except Exception as e:
        traceback.print_exc()
        raise SystemExit(
            "hitl_foundationpose: building FoundationPose's scorer, refiner and rasteriser "
            "failed ({}: {}). Check that {} holds weights/{}/ and weights/{}/ (model_best.pth "
            "and config.yml each), that build_all.sh has run and that a CUDA GPU is visible."
            .format(type(e).__name__, e, directory, WEIGHTS[0], WEIGHTS[1]))


def serve(conn, fp, shared, options, log):
    """One connection, until the client closes it or breaks the protocol."""
    header, arrays = wire.read_message(conn)
    if header["type"] != "hello":
        wire.send(conn, wire.error("the first message must be `hello`"))
        return
    if header.get("protocol") != wire.PROTOCOL or header.get("version") != wire.VERSION:
        wire.send(conn, wire.hello_reply(False, reason="this peer speaks {} version {} only"
                                         .format(wire.PROTOCOL, wire.VERSION)))
        return
    try:
        vertices, faces = wire.check_mesh(arrays)
    except wire.ProtocolError as e:
        wire.send(conn, wire.hello_reply(False, reason=str(e)))
        return
    try:
        session = Session(fp, shared, vertices, faces, options)
    except Exception as e:
        traceback.print_exc()
        wire.send(conn, wire.hello_reply(False, reason="FoundationPose could not take the mesh: "
                                         "{}: {}".format(type(e).__name__, e)))
        return
    try:
        wire.send(conn, wire.hello_reply(True, estimator=session.describe()))
        log("accepted {!r}: {} vertices, {} triangles".format(
            header.get("client"), len(vertices), len(faces)))
        while True:
            try:
                header, arrays = wire.read_message(conn)
            except wire.ProtocolError as e:
                wire.send(conn, wire.error(str(e)))
                return  # out of step: end the connection
            kind = header["type"]
            if kind == "reset":
                session.reset()
                wire.send(conn, {"type": "reset"})
            elif kind == "frame":
                try:
                    reply = session.frame(header, arrays)
                except FrameRefused as e:
                    log(str(e))
                    reply = wire.error(str(e))
                except Exception as e:  # anything else: say so, keep serving, start over
                    traceback.print_exc()
                    session.reset()
                    reply = wire.error("the FoundationPose peer failed on frame {}: {}: {}"
                                       .format(header.get("seq"), type(e).__name__, e))
                wire.send(conn, reply)
            else:
                wire.send(conn, wire.error("unknown message type {!r}".format(kind)))
    finally:
        session.close()


def parse_color(text):
    try:
        rgb = [int(x) for x in text.split(",")]
    except ValueError:
        rgb = []
    if len(rgb) != 3 or not all(0 <= c <= 255 for c in rgb):
        raise argparse.ArgumentTypeError("expected R,G,B with each 0..255, got {!r}".format(text))
    return rgb


def main(argv=None):
    p = argparse.ArgumentParser(
        prog="python -m hitl_foundationpose", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("socket", help="path of the Unix socket to listen on (replaced if it exists)")
    p.add_argument("--foundationpose-dir", default=os.environ.get("FOUNDATIONPOSE_DIR"),
                   help="the FoundationPose checkout (default: $FOUNDATIONPOSE_DIR)")
    p.add_argument("--register-iterations", type=int, default=5,
                   help="refiner iterations of register (default 5, FoundationPose's demo)")
    p.add_argument("--track-iterations", type=int, default=2,
                   help="refiner iterations of track_one (default 2, FoundationPose's demo)")
    p.add_argument("--rescale-tolerance", type=float, default=0.0,
                   help="keep the estimator's mesh scale while a frame's median target depth "
                        "is within this fraction of it (default 0: rescale on every change, the "
                        "paper exactly; each rescale rebuilds FoundationPose's mesh)")
    p.add_argument("--mesh-color", type=parse_color, default=None, metavar="R,G,B",
                   help="paint the mesh one colour for FoundationPose's RGB rendering (default: "
                        "trimesh's grey 102,102,102, what FoundationPose sees for any "
                        "untextured mesh)")
    p.add_argument("--debug", type=int, default=0, help="FoundationPose's debug level")
    p.add_argument("--debug-dir", default=None,
                   help="FoundationPose's debug folder (default: a new temporary folder)")
    p.add_argument("--quiet", action="store_true", help="no log on stderr")
    args = p.parse_args(argv)
    if not args.foundationpose_dir:
        p.error("--foundationpose-dir (or $FOUNDATIONPOSE_DIR) is required")
    if args.register_iterations < 1 or args.track_iterations < 1:
        p.error("iterations must be >= 1")
    if not (args.rescale_tolerance >= 0 and args.rescale_tolerance < 1):
        p.error("--rescale-tolerance must be in [0, 1)")

    log = (lambda msg: None) if args.quiet else stderr_log("hitl_foundationpose")
    options = Options(
        register_iterations=args.register_iterations, track_iterations=args.track_iterations,
        rescale_tolerance=args.rescale_tolerance, mesh_color=args.mesh_color, debug=args.debug,
        debug_dir=args.debug_dir or tempfile.mkdtemp(prefix="hitl-foundationpose-"), log=log)

    fp = load_foundationpose(args.foundationpose_dir)
    shared = build_shared(fp, os.path.abspath(args.foundationpose_dir))
    log("scorer, refiner and rasteriser built")

    path = args.socket
    tmp = "{}.{}.tmp".format(path, os.getpid())
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
    log("listening on {}".format(path))
    while True:
        conn, _ = server.accept()
        with conn:
            try:
                serve(conn, fp, shared, options, log)
            except wire.Closed as e:
                if str(e):
                    log("client: {}".format(e))
            except wire.ProtocolError as e:
                log("client broke the protocol: {}".format(e))
            except OSError as e:
                log("connection failed: {}".format(e))
        log("connection ended")
