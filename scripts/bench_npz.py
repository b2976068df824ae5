#!/usr/bin/env python3
"""Side-by-side for `hitl bench npz`: time numpy's np.load of the same NPZ files.

hitl's benchmark (`hitl_trajectories::bench::bench_npz`) leaves its files in
$TMPDIR/hitl-bench-npz/traj-<N>-{stored,deflated}.npz. This script loads each with numpy, reading
every array (np.load of an .npz is lazy, so each key is read to make the comparison fair), and
prints one JSON object with the median of 5 runs in milliseconds.

Usage: .venv/bin/python scripts/bench_npz.py [--waypoints 100000] [FILE.npz ...]
If no hitl-written file exists yet, it writes a numpy one of the same layout first (and says so).
"""
import argparse
import json
import os
import statistics
import sys
import tempfile
import time

import numpy as np

REPEATS = 5


def load_all(path):
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def median_ms(fn):
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def numpy_written(n, directory):
    """The same layout as hitl's synthetic trajectory, written by numpy."""
    t = np.arange(n) * 0.01
    span = t[-1]
    base = np.array([0.0, -0.4, 0.0, 1.4, 0.0, 1.5, 0.0])
    w = 2 * np.pi * (1 + np.arange(7)) / span
    q = base + 0.1 * np.sin(np.outer(t, w)) ** 2
    s, c = np.sin(t), np.cos(t)
    pose = np.zeros((n, 4, 4))
    pose[:, 0, 0], pose[:, 0, 1], pose[:, 1, 0], pose[:, 1, 1] = c, -s, s, c
    pose[:, 2, 2] = pose[:, 3, 3] = 1.0
    arrays = dict(
        qpos=q, t=t, capture=(np.arange(n) % 25 == 0),
        light=((np.arange(n) % 100) / 100).astype(np.float32),
        u_rad=t / span * 2 * np.pi, rel_pos_rtn_m=np.stack([c, s, 0.1 * t], axis=1),
        cam_pose_base=pose, sun_phase_deg=(t * 3.6) % 360,
        meta=np.array(json.dumps({"preset": "bench", "scale": 1.0})),
    )
    paths = []
    for name, save in (("stored", np.savez), ("deflated", np.savez_compressed)):
        p = os.path.join(directory, f"numpy-{n}-{name}.npz")
        save(p, **arrays)
        paths.append(p)
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--waypoints", type=int, default=100_000)
    ap.add_argument("files", nargs="*")
    args = ap.parse_args()
    directory = os.path.join(tempfile.gettempdir(), "hitl-bench-npz")
    files = args.files or [
        os.path.join(directory, f"traj-{args.waypoints}-{k}.npz") for k in ("stored", "deflated")
    ]
    note = "hitl-written files"
    if not all(os.path.exists(f) for f in files):
        os.makedirs(directory, exist_ok=True)
        files = numpy_written(args.waypoints, directory)
        note = "numpy-written files (run `hitl bench npz` first to time hitl's own files)"
    out = {"numpy": np.__version__, "python": sys.version.split()[0], "source": note,
           "repeats": REPEATS, "statistic": "median", "files": {}}
    for f in files:
        arrays = load_all(f)
        out["files"][os.path.basename(f)] = {
            "bytes": os.path.getsize(f),
            "waypoints": int(arrays["qpos"].shape[0]),
            "np_load_ms": median_ms(lambda: load_all(f)),
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
