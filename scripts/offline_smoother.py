#!/usr/bin/env python3
"""What smoothing a recorded run's estimates over time would bring (issue 23's experiment).

A fixed-interval smoother over a whole recording: each frame's rotation estimate is a measurement
whose noise is the frame's Cramer-Rao bound (its turns' axes and 1-sigma from
`first_view_bound ... all` with COV=1) times NOISE_FACTOR, the loosest capped at 30 deg; between
frames, the turn from one capture to the next is held near the previous one (its change has a
deviation of TURN_CHANGE_DEG per capture). Frames far from the smoothed track are down-weighted
(Cauchy, 3 sigma). Prints the paper's mean e_r (first-frame calibration) before and after.
Offline: it reads every frame before it smooths the first, so a tracker built on it would
publish its estimates late. Ground truth is read only to score.

usage: offline_smoother.py REC.mcap COV.txt [NOISE_FACTOR [TURN_CHANGE_DEG]]
  COV.txt: COV=1 cargo run --release -p hitl-perception --example first_view_bound -- REC.mcap all | grep ^cov
"""
import sys

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation as R


def poses(path):
    gt, est = {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, ch, msg, dec in reader.iter_decoded_messages(topics=["/pose/gt", "/pose/estimate"]):
            q = dec.pose.orientation
            (gt if ch.topic == "/pose/gt" else est)[msg.log_time] = R.from_quat([q.x, q.y, q.z, q.w])
    return gt, est


def mean_er(rs, gts):
    offset = rs[0].inv() * gts[0]
    return np.mean([np.degrees(((r * offset).inv() * g).magnitude()) for r, g in zip(rs, gts)])


def main():
    rec, cov = sys.argv[1], sys.argv[2]
    factor = float(sys.argv[3]) if len(sys.argv) > 3 else 2.0
    change = np.radians(float(sys.argv[4]) if len(sys.argv) > 4 else 4.0)
    gt, est = poses(rec)
    info = {}
    for line in open(cov):
        v = line.split()
        turns = np.array(v[2:], float).reshape(3, 4)
        info[int(v[1])] = sum(
            np.outer(a[:3], a[:3]) / (min(a[3], np.radians(30)) * factor) ** 2 for a in turns
        )
    stamps = [t for t in sorted(gt) if t in est and t in info]
    z = [est[t] for t in stamps]
    # Each frame's information in the target's axes (camera turns carried by the estimate).
    w = [
        np.linalg.cholesky(r.as_matrix().T @ info[t] @ r.as_matrix() + 1e-9 * np.eye(3)).T
        for r, t in zip(z, stamps)
    ]
    n = len(z)
    weight, x = np.ones(n), np.zeros(3 * n)
    for _ in range(5):
        def residuals(x):
            rs = [z[i] * R.from_rotvec(x[3 * i:3 * i + 3]) for i in range(n)]
            out = [np.sqrt(weight[i]) * (w[i] @ x[3 * i:3 * i + 3]) for i in range(n)]
            for i in range(1, n - 1):
                before = (rs[i - 1].inv() * rs[i]).as_rotvec()
                after = (rs[i].inv() * rs[i + 1]).as_rotvec()
                out.append((after - before) / change)
            return np.concatenate(out)

        x = least_squares(residuals, x).x
        d = np.array([np.linalg.norm(w[i] @ x[3 * i:3 * i + 3]) for i in range(n)])
        weight = 1.0 / (1.0 + (d / 3.0) ** 2)
    smoothed = [z[i] * R.from_rotvec(x[3 * i:3 * i + 3]) for i in range(n)]
    gts = [gt[t] for t in stamps]
    print(f"{rec}: {n} frames, mean e_r {mean_er(z, gts):.2f} deg before, "
          f"{mean_er(smoothed, gts):.2f} after")


if __name__ == "__main__":
    main()
