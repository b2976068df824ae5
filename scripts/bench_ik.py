#!/usr/bin/env python3
"""Side-by-side IK benchmark: ikpy (PyPI) on the camera poses of a plan made by `hitl plan`.

Usage (from the repository root, after `make setup` and `pip install -r scripts/requirements-test.txt`):

    hitl plan --preset flyaround --duration-s 60 --waypoints 3600 --out /tmp/bench-ik.npz
    .venv/bin/python scripts/bench_ik.py /tmp/bench-ik.npz [--limit N] [--rust-json FILE]

The script builds the xArm7 chain with the camera mount from the plan's `meta`, then solves every
`cam_pose_base` with ikpy (full pose, warm-started from the previous solution, like the planner's
own solver), and measures both solvers' accuracy the same way: ikpy's forward kinematics of each
solution against the planned camera pose (for hitl, of the plan's `qpos`). `--rust-json` takes the
JSON of `hitl bench ik --json` (or of `bench_ik`) for the speed ratio. Prints one JSON object.
"""

import argparse
import json
import sys
import time

try:
    import numpy as np
    from ikpy.chain import Chain
    from ikpy.link import OriginLink, URDFLink
    from scipy.spatial.transform import Rotation
except ImportError as e:  # pragma: no cover
    sys.exit(f"bench_ik.py: {e}: run make setup, then pip install -r scripts/requirements-test.txt")

# The public xArm7 chain (shared/reference/FACTS.md): child offset (m) and rotation about the
# parent's x (rad); each joint turns about its own z.
CHAIN = [
    ((0.0, 0.0, 0.267), 0.0),
    ((0.0, 0.0, 0.0), -np.pi / 2),
    ((0.0, -0.293, 0.0), np.pi / 2),
    ((0.0525, 0.0, 0.0), np.pi / 2),
    ((0.0775, -0.3425, 0.0), np.pi / 2),
    ((0.0, 0.0, 0.0), np.pi / 2),
    ((0.076, 0.097, 0.0), -np.pi / 2),
]
LIMITS = [
    (-2 * np.pi, 2 * np.pi),
    (-2.059488, 2.094395),
    (-2 * np.pi, 2 * np.pi),
    (-0.191986, 3.92699),
    (-2 * np.pi, 2 * np.pi),
    (-1.692969, np.pi),
    (-2 * np.pi, 2 * np.pi),
]


def build_chain(mount):
    links = [OriginLink()]
    for i, ((x, y, z), rx) in enumerate(CHAIN):
        links.append(
            URDFLink(
                name=f"joint{i + 1}",
                origin_translation=np.array([x, y, z]),
                origin_orientation=np.array([rx, 0.0, 0.0]),
                rotation=np.array([0.0, 0.0, 1.0]),
                bounds=LIMITS[i],
            )
        )
    rpy = Rotation.from_matrix(mount[:3, :3]).as_euler("xyz")
    links.append(
        URDFLink(
            name="camera",
            origin_translation=mount[:3, 3],
            origin_orientation=rpy,
            rotation=None,
            joint_type="fixed",
        )
    )
    mask = [False] + [True] * 7 + [False]
    return Chain(name="xarm7_camera", links=links, active_links_mask=mask)


def pose_error(chain, q7, target):
    full = np.concatenate([[0.0], q7, [0.0]])
    got = chain.forward_kinematics(full)
    dp = np.linalg.norm(got[:3, 3] - target[:3, 3])
    r = got[:3, :3].T @ target[:3, :3]
    # The rotation vector's length: exact near zero, unlike arccos of the trace.
    ang = np.degrees(Rotation.from_matrix(r).magnitude())
    return dp, ang


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("npz")
    ap.add_argument("--limit", type=int, default=0, help="solve only the first N poses")
    ap.add_argument("--rust-json", help="figures of `hitl bench ik --json`")
    args = ap.parse_args()

    data = np.load(args.npz)
    meta = json.loads(str(data["meta"]))
    mount = np.array(meta["camera_mount"], dtype=float)
    poses = np.asarray(data["cam_pose_base"], dtype=float)
    qpos = np.asarray(data["qpos"], dtype=float)
    n = len(poses) if args.limit <= 0 else min(args.limit, len(poses))
    chain = build_chain(mount)

    # The hitl solution's accuracy, measured by ikpy's own forward kinematics.
    hitl_err = [pose_error(chain, qpos[k], poses[k]) for k in range(n)]

    q = np.concatenate([[0.0], qpos[0], [0.0]])  # warm start where the plan starts
    errs = []
    t0 = time.perf_counter()
    for k in range(n):
        target = poses[k]
        q = chain.inverse_kinematics_frame(target, initial_position=q, orientation_mode="all")
        errs.append(pose_error(chain, q[1:8], target))
    elapsed = time.perf_counter() - t0

    out = {
        "bench": "ik-side-by-side",
        "poses": n,
        "ikpy": {
            "version": __import__("ikpy").__version__,
            "total_s": elapsed,
            "us_per_pose": elapsed * 1e6 / n,
            "max_pos_err_m": max(e[0] for e in errs),
            "max_rot_err_deg": max(e[1] for e in errs),
            "median_pos_err_m": float(np.median([e[0] for e in errs])),
        },
        "hitl_plan_accuracy": {
            "max_pos_err_m": max(e[0] for e in hitl_err),
            "max_rot_err_deg": max(e[1] for e in hitl_err),
        },
    }
    if args.rust_json:
        with open(args.rust_json) as f:
            rust = json.load(f)
        us = rust.get("track_us_per_waypoint")
        out["hitl"] = rust
        if us:
            out["speedup"] = out["ikpy"]["us_per_pose"] / us
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
