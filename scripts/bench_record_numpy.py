#!/usr/bin/env python3
"""The paper's way of recording depth: one numpy `savez_compressed` file per depth frame.

Times it on the same synthetic frames as `hitl bench record` (hitl_record::bench: the same
integer formula, 1280x800 uint16 millimetres), so the two figures compare like for like.
Prints one JSON object: frames/s, MB/s of raw depth, file size per frame.

usage: bench_record_numpy.py [--seconds S] [--frames N] [--out DIR]
"""
import argparse
import json
import os
import shutil
import tempfile
import time

import numpy as np

W, H = 1280, 800


def synthetic_depth_mm(k: int) -> np.ndarray:
    """Frame k, exactly as hitl_record::bench::synthetic_depth_mm."""
    y, x = np.mgrid[0:H, 0:W].astype(np.uint32)
    kk = np.uint32(k)
    with np.errstate(over="ignore"):
        h = (x * np.uint32(73856093)) ^ (y * np.uint32(19349663)) ^ (kk * np.uint32(83492791))
    cx = np.uint32(640 + (k % 8) * 10)
    dx = np.where(x >= cx, x - cx, cx - x)
    dy = np.where(y >= 400, y - 400, 400 - y)
    r2 = dx * dx + dy * dy
    base = np.where(r2 < 250 * 250, 900 + r2 // 400, 2000 + y // 2)
    d = np.where(h % 97 == 0, 0, base + h % 9)
    return d.astype(np.uint16)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--frames", type=int, default=0, help="stop after N frames (0: by time)")
    ap.add_argument("--out", default=None, help="folder to write into (default: a temp folder)")
    a = ap.parse_args()
    frames = [synthetic_depth_mm(k) for k in range(4)]
    out = a.out or tempfile.mkdtemp(prefix="hitl-bench-numpy-")
    os.makedirs(out, exist_ok=True)
    n, size = 0, 0
    t0 = time.perf_counter()
    c0 = time.process_time()
    while True:
        p = os.path.join(out, f"depth_{n:06d}.npz")
        np.savez_compressed(p, depth=frames[n % len(frames)])
        size += os.path.getsize(p)
        n += 1
        el = time.perf_counter() - t0
        if (a.frames and n >= a.frames) or (not a.frames and el >= a.seconds):
            break
    el = time.perf_counter() - t0
    cpu = time.process_time() - c0
    if a.out is None:
        shutil.rmtree(out, ignore_errors=True)
    print(json.dumps({
        "writer": "numpy savez_compressed per depth frame",
        "frames": n,
        "seconds": el,
        "frames_per_s": n / el,
        "cpu_s": cpu,
        "frames_per_cpu_s": n / cpu if cpu > 0 else None,
        "depth_mb_per_s": n * W * H * 2 / 1e6 / el,
        "file_kb_per_frame": size / n / 1e3,
        "numpy": np.__version__,
    }))


if __name__ == "__main__":
    main()
