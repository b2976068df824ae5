"""Frames, a mesh and the stand-in FoundationPose for the tests."""
import os

import numpy as np

from hitl_foundationpose import peer

STAND_IN_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "stand_in")
H, W = 24, 32
FX, FY, CX, CY = 40.0, 41.0, 15.5, 11.5
K = np.array([[FX, 0, CX], [0, FY, CY], [0, 0, 1.0]])


def stand_in():
    """The stand-in module, loaded the way the peer loads FoundationPose, its call log cleared."""
    fp = peer.load_foundationpose(STAND_IN_DIR)
    assert fp.__file__.startswith(STAND_IN_DIR), fp.__file__
    del fp.CALLS[:]
    return fp


def box_mesh(size=0.4):
    """A box centred on the origin: (vertices [8,3] f64, triangles [12,3])."""
    s = size / 2
    v = np.array([[x, y, z] for x in (-s, s) for y in (-s, s) for z in (-s, s)], dtype=np.float64)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]],
                 dtype=np.int64)
    return v, f


def frame(seq, median_m, mask=True, color=True, invalid=True):
    """A `frame` header and payloads: a target rectangle of 17 columns x 12 rows whose depth runs
    linearly across the columns with median exactly `median_m` (the middle column). With
    `invalid`, four target pixels carry NaN, +inf, -1 and 0 in pairs at both ends of the depth
    range, so treating them as no return keeps the median."""
    depth = np.zeros((H, W), dtype=np.float32)
    cols = np.arange(8, 25)  # 17 columns, middle column 16
    rows = np.arange(6, 18)
    for u in cols:
        depth[rows, u] = median_m * (1.0 + 0.01 * (u - 16))
    m = np.zeros((H, W), dtype=np.uint8)
    m[6:18, 8:25] = 255
    if invalid:
        depth[6, 8], depth[6, 24] = np.nan, np.inf
        depth[7, 8], depth[7, 24] = -1.0, 0.0
    header = {"type": "frame", "seq": seq, "timestamp_ns": 1000 + seq,
              "intrinsics": {"fx": FX, "fy": FY, "cx": CX, "cy": CY, "width": W, "height": H}}
    arrays = {"depth": depth}
    if color:
        arrays["color"] = np.full((H, W, 3), 90, dtype=np.uint8)
    if mask:
        arrays["mask"] = m
    return header, arrays


def true_centroid(arrays):
    """The back-projected centroid of the target pixels with a finite, positive depth, in the
    frame's own metres: what the stand-in's estimate must come back as."""
    d = arrays["depth"].astype(np.float64)
    valid = np.isfinite(d) & (d > 0) & (arrays["mask"] != 0)
    v, u = np.nonzero(valid)
    z = d[v, u]
    return np.array([((u - CX) / FX * z).mean(), ((v - CY) / FY * z).mean(), z.mean()])


def reply_pose(reply):
    return np.array(reply["pose"], dtype=np.float64).reshape(4, 4)


def calls(fp, name=None):
    return [c for c in fp.CALLS if name is None or c["call"] == name]
