"""A stand-in for FoundationPose's `estimater` module (no CUDA, no networks), with the names and
signatures hitl_foundationpose uses from NVlabs/FoundationPose's estimater.py and run_demo.py:
`ScorePredictor()`, `PoseRefinePredictor()`, `dr.RasterizeCudaContext()`,
`FoundationPose(model_pts, model_normals, symmetry_tfs=None, mesh=None, scorer=None,
refiner=None, glctx=None, debug=0, debug_dir=...)` with `reset_object`, `register`, `track_one`
and the remembered `pose_last`.

It records every call (module list CALLS; and one JSON line per call in the file named by
$HITL_FP_STAND_IN_LOG, for tests in another process) with what it saw: the median target depth,
non-finite depth values, the mesh's greatest dimension, iterations. Its "estimate" is simple and
checkable: rotation R_FIXED (30 deg about z), translation the back-projected centroid of the
valid depth pixels it was given (within the mask for `register`, all of them for `track_one`,
which has no mask), in whatever metres it was handed. Like the real one it returns the identity
rotation when fewer than 4 target pixels have depth, refuses `track_one` before a `register`,
creates debug_dir, and writes each mesh it is given to a file (`mesh_path`) it never removes.
"""
import json
import os
import tempfile
import types
import uuid

import numpy as np

CALLS = []
C, S = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
R_FIXED = np.array([[C, -S, 0.0], [S, C, 0.0], [0.0, 0.0, 1.0]])


def record(call, **fields):
    entry = dict(call=call, **fields)
    CALLS.append(entry)
    path = os.environ.get("HITL_FP_STAND_IN_LOG")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps(entry) + "\n")


class ScorePredictor(object):
    def __init__(self, amp=True):
        record("ScorePredictor")


class PoseRefinePredictor(object):
    def __init__(self,):
        record("PoseRefinePredictor")


class RasterizeCudaContext(object):
    def __init__(self, device=None):
        record("RasterizeCudaContext")


dr = types.SimpleNamespace(RasterizeCudaContext=RasterizeCudaContext)


def _centroid(depth, K, valid):
    v, u = np.nonzero(valid)
    z = depth[v, u]
    x = (u - K[0, 2]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    return np.array([x.mean(), y.mean(), z.mean()])


def _check_image(rgb, depth, K):
    assert isinstance(K, np.ndarray) and K.shape == (3, 3), "K must be a 3x3 array"
    assert isinstance(depth, np.ndarray) and depth.ndim == 2, "depth must be [H,W]"
    assert isinstance(rgb, np.ndarray) and rgb.dtype == np.uint8, "rgb must be uint8"
    assert rgb.shape == depth.shape + (3,), "rgb must be [H,W,3]"
    assert rgb.flags.writeable, "rgb must be writable (FoundationPose's cv2 calls write)"


class FoundationPose(object):
    def __init__(self, model_pts, model_normals, symmetry_tfs=None, mesh=None, scorer=None,
                 refiner=None, glctx=None, debug=0,
                 debug_dir='/home/bowen/debug/novel_pose_debug/'):
        os.makedirs(debug_dir, exist_ok=True)
        self.scorer = scorer if scorer is not None else ScorePredictor()
        self.refiner = refiner if refiner is not None else PoseRefinePredictor()
        self.glctx = glctx
        record("FoundationPose", shared=scorer is not None and refiner is not None
               and glctx is not None, debug=debug)
        self.reset_object(model_pts, model_normals, symmetry_tfs=symmetry_tfs, mesh=mesh)
        self.pose_last = None

    def reset_object(self, model_pts, model_normals, symmetry_tfs=None, mesh=None):
        v = np.asarray(mesh.vertices)
        assert np.asarray(model_pts).shape == v.shape, "model_pts must be the mesh's vertices"
        assert np.asarray(model_normals).shape == v.shape, "one normal per vertex"
        self.model_center = (v.min(axis=0) + v.max(axis=0)) / 2
        self.mesh = mesh
        self.mesh_path = os.path.join(tempfile.gettempdir(),
                                      "hitl-fp-stand-in-{}.obj".format(uuid.uuid4()))
        with open(self.mesh_path, "w") as f:
            f.write("# stand-in\n")
        record("reset_object", extent=float((v.max(axis=0) - v.min(axis=0)).max()),
               vertices=len(v), mesh_path=self.mesh_path,
               color=[int(c) for c in np.asarray(mesh.visual.vertex_colors)[0][:3]])

    def _tf_to_centered(self):
        tf = np.eye(4)
        tf[:3, 3] = -self.model_center
        return tf

    def register(self, K, rgb, depth, ob_mask, ob_id=None, glctx=None, iteration=5):
        _check_image(rgb, depth, K)
        assert ob_mask.dtype == bool and ob_mask.shape == depth.shape, "ob_mask must be bool [H,W]"
        valid = (depth >= 0.001) & ob_mask
        pose = np.eye(4)
        if valid.sum() < 4:  # the real one's answer: identity rotation, a guessed translation
            if valid.any():
                pose[:3, 3] = _centroid(depth, K, valid)
        else:
            pose[:3, :3] = R_FIXED
            pose[:3, 3] = _centroid(depth, K, valid)
            self.pose_last = pose @ np.linalg.inv(self._tf_to_centered())
        record("register", iteration=iteration, median_depth=_median(depth, valid),
               nonfinite=int((~np.isfinite(depth)).sum()), valid=int(valid.sum()),
               returned_t=[float(x) for x in pose[:3, 3]])
        return pose

    def track_one(self, rgb, depth, K, iteration, extra={}):
        if self.pose_last is None:
            raise RuntimeError
        _check_image(rgb, depth, K)
        last = np.asarray(self.pose_last).reshape(4, 4)
        valid = depth >= 0.001
        pose = np.eye(4)
        pose[:3, :3] = last[:3, :3]
        pose[:3, 3] = _centroid(depth, K, valid)
        record("track_one", iteration=iteration, median_depth=_median(depth, valid),
               nonfinite=int((~np.isfinite(depth)).sum()),
               pose_last_t=[float(x) for x in (last @ self._tf_to_centered())[:3, 3]],
               returned_t=[float(x) for x in pose[:3, 3]])
        self.pose_last = (pose @ np.linalg.inv(self._tf_to_centered())).reshape(1, 4, 4)
        return pose


def _median(depth, valid):
    return float(np.median(depth[valid])) if valid.any() else None
