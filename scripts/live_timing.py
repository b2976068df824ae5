#!/usr/bin/env python3
"""The loop's wake lateness with and without a Foxglove viewer on `hitl run --live`.

Reproduces the "Timing with a viewer" series of docs/live.md: plans the 20 s fly-around, then
plays it PAIRS times without a viewer and PAIRS times with one, interleaved (without, with, ...),
each run recorded; the viewer is a Foxglove WebSocket client (subprotocol foxglove.sdk.v1, the
`websockets` package) that subscribes to every channel the run advertises and counts what it
receives. Each run's lateness comes from its recording (`hitl report RUN.mcap --json`,
timing.wake_late_us); the table is printed and written as JSON.

Usage: scripts/live_timing.py [--hitl target/release/hitl] [--pairs 3] [--out runs/live-timing]
Exits 1 if a run does not complete (its exit code is printed), 2 on bad arguments.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import threading
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

RUN_FLAGS = [
    "--camera", "sim", "--camera-preset", "wfov", "--camera-size", "320x256",
    "--light", "sim", "--config", "tests/data/shared-vm-lab.toml", "--plain",
]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Viewer(threading.Thread):
    """Subscribes to every advertised channel and counts messages, bytes and images."""

    def __init__(self, port):
        super().__init__(daemon=True)
        self.port = port
        self.messages = 0
        self.bytes = 0
        self.images = 0
        self.connected = False
        self.error = None

    def run(self):
        deadline = time.monotonic() + 60
        ws = None
        while ws is None:
            try:
                ws = connect(f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"],
                             max_size=None, open_timeout=2)
            except (OSError, TimeoutError):
                if time.monotonic() > deadline:
                    self.error = "no live server within 60 s"
                    return
                time.sleep(0.1)
        self.connected = True
        image_subs = set()
        next_sub = 1
        try:
            for msg in ws:
                if isinstance(msg, str):
                    m = json.loads(msg)
                    if m.get("op") == "advertise":
                        subs = []
                        for ch in m.get("channels", []):
                            subs.append({"id": next_sub, "channelId": ch["id"]})
                            if "image" in ch.get("topic", "") or "color" in ch.get("topic", ""):
                                image_subs.add(next_sub)
                            next_sub += 1
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                else:
                    self.messages += 1
                    self.bytes += len(msg)
                    # Binary message data: opcode 1, subscription id (u32 little-endian), ...
                    if len(msg) >= 5 and msg[0] == 1:
                        if int.from_bytes(msg[1:5], "little") in image_subs:
                            self.images += 1
        except ConnectionClosed:
            pass


def lateness(hitl, mcap):
    out = subprocess.run([hitl, "report", mcap, "--json"], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"hitl report {mcap} failed: {out.stderr}")
    summary = json.loads(out.stdout)
    timing = summary["timing"]
    late = timing["wake_late_us"]
    return {"p50_us": late["p50"], "p99_us": late["p99"], "max_us": late["max"],
            "overruns": timing["overruns"], "ticks": timing["ticks"]}


def play(hitl, traj, mcap, with_viewer):
    cmd = [hitl, "run", traj, "--record", mcap] + RUN_FLAGS
    viewer = None
    if with_viewer:
        port = free_port()
        cmd += [f"--live=127.0.0.1:{port}"]
        viewer = Viewer(port)
        viewer.start()
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        print(run.stdout + run.stderr, file=sys.stderr)
        sys.exit(f"a run {'with' if with_viewer else 'without'} a viewer exited {run.returncode}")
    row = lateness(hitl, mcap)
    row["viewer"] = with_viewer
    if viewer is not None:
        viewer.join(timeout=10)
        if viewer.error or not viewer.connected:
            sys.exit(f"the viewer failed: {viewer.error}")
        row.update(messages=viewer.messages, bytes=viewer.bytes, images=viewer.images)
        dropped = [ln for ln in run.stdout.splitlines() + run.stderr.splitlines()
                   if "live" in ln and "drop" in ln]
        row["live_line"] = dropped[-1].strip() if dropped else ""
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hitl", default="target/release/hitl", help="the hitl binary")
    ap.add_argument("--pairs", type=int, default=3, help="runs with and without a viewer, each")
    ap.add_argument("--out", default="runs/live-timing", help="folder for the runs and JSON")
    a = ap.parse_args()
    if a.pairs < 1 or not os.access(a.hitl, os.X_OK):
        ap.error("--pairs must be >= 1 and --hitl an executable (make build)")
    os.makedirs(a.out, exist_ok=True)
    traj = os.path.join(a.out, "fly.npz")
    subprocess.run([a.hitl, "plan", "--preset", "flyaround", "--range-m", "10", "--duration-s",
                    "20", "--capture-every", "25", "--out", traj], check=True,
                   capture_output=True)
    rows = []
    for i in range(a.pairs):
        for with_viewer in (False, True):
            mcap = os.path.join(a.out, f"run-{i}-{'viewer' if with_viewer else 'none'}.mcap")
            row = play(a.hitl, traj, mcap, with_viewer)
            rows.append(row)
            extra = (f", viewer got {row['messages']} messages ({row['bytes'] / 1e6:.1f} MB), "
                     f"{row['images']} images" if with_viewer else "")
            print(f"pair {i + 1} {'one viewer' if with_viewer else 'no viewer '}: "
                  f"p50 {row['p50_us']:.1f} us, p99 {row['p99_us']:.1f} us, "
                  f"max {row['max_us'] / 1e3:.1f} ms, {row['overruns']} overruns{extra}",
                  flush=True)
            os.remove(mcap)
    with open(os.path.join(a.out, "live-timing.json"), "w") as f:
        json.dump(rows, f, indent=1)
    print("\n| | p50 | p99 | max | overruns |\n| --- | --- | --- | --- | --- |")
    for with_viewer, name in ((False, "no viewer"), (True, "one viewer")):
        r = [x for x in rows if x["viewer"] == with_viewer]

        def span(key, scale=1.0, fmt="{:.1f}"):
            lo, hi = min(x[key] for x in r) * scale, max(x[key] for x in r) * scale
            return f"{fmt.format(lo)}-{fmt.format(hi)}"
        print(f"| {name} | {span('p50_us')} us | {span('p99_us', fmt='{:.0f}')} us | "
              f"{span('max_us', 1e-3)} ms | {span('overruns', fmt='{:.0f}')} |")


if __name__ == "__main__":
    main()
