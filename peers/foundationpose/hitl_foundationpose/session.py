"""One client's FoundationPose session: the mesh from its `hello`, then frame by frame register or
track, with the DreamSat-Bench paper's depth normalisation around every FoundationPose call.

- Registration (`FoundationPose.register`, 5 refiner iterations by default) on the first frame of a
  connection, after a `reset`, and after a frame that was lost or failed; tracking
  (`FoundationPose.track_one`, 2 iterations) otherwise.
- Depth normalisation (the paper, "Depth normalization"): non-finite or negative depth is no
  return (0); k = median depth of the target (mask and valid depth) / 1 m; FoundationPose sees
  depth / k and the mesh scaled by 1 / k (a similarity about the camera origin, so the target
  covers the same pixels); the translation it returns is multiplied by k; rotation and
  intrinsics are unchanged. Between two tracked frames whose k differ, the remembered pose
  (`pose_last`, in the previous frame's normalised metres) is rescaled by k_old / k_new.
- Refused with an `error` reply (state unchanged): a frame without a mask (registration needs
  FoundationPose's `ob_mask`, and k is a median over the mask), without colour, or whose
  payloads do not match its intrinsics.
- Lost (pose null): no target pixel with depth, a pose that is not finite, or FoundationPose's
  own "could not register" answer (an exact identity rotation: `register` returns one when fewer
  than 4 target pixels survive its depth filters; the paper takes identity as lost).

Nothing here touches the socket ([`peer`] does) or imports CUDA: FoundationPose's module is passed
in, so the tests drive this with a stand-in of the same signatures.
"""
import os
import sys

import numpy as np


class FrameRefused(Exception):
    """A frame this session cannot serve; the reason goes back in an `error` reply."""


class Options(object):
    """Settings of every session (the command line's)."""

    def __init__(self, register_iterations=5, track_iterations=2, rescale_tolerance=0.0,
                 mesh_color=None, debug=0, debug_dir=None, log=None):
        self.register_iterations = register_iterations
        self.track_iterations = track_iterations
        # 0: the paper exactly, k from every frame's median (the mesh is rebuilt whenever k
        # changes). > 0: keep the mesh's k while the frame's k is within this fraction of it.
        self.rescale_tolerance = rescale_tolerance
        self.mesh_color = mesh_color
        self.debug = debug
        self.debug_dir = debug_dir
        self.log = log or (lambda msg: None)


class Shared(object):
    """What the peer builds once and every session uses: FoundationPose's scorer and refiner
    networks and its CUDA rasteriser context."""

    def __init__(self, fp):
        self.scorer = fp.ScorePredictor()
        self.refiner = fp.PoseRefinePredictor()
        self.glctx = fp.dr.RasterizeCudaContext()


def valid_depth(depth):
    """Depth in float64 metres with every non-finite or negative value set to 0 (no return)."""
    z = np.array(depth, dtype=np.float64)
    z[~np.isfinite(z) | (z < 0)] = 0.0
    return z


def normaliser(depth, target):
    """k = median depth over `target` pixels with a return (depth > 0), / 1 m; None if none."""
    z = depth[target & (depth > 0)]
    if z.size == 0:
        return None
    return float(np.median(z)) / 1.0


def _copy_pose(p):
    """A copy of FoundationPose's remembered pose (a torch tensor there, numpy in tests)."""
    return p.clone() if hasattr(p, "clone") else np.array(p, copy=True)


class Session(object):
    def __init__(self, fp, shared, vertices, faces, options):
        import trimesh  # in FoundationPose's environment; imported late so --help needs numpy only

        self.fp, self.shared, self.opt = fp, shared, options
        colors = None
        if options.mesh_color is not None:
            colors = np.tile(np.array(list(options.mesh_color) + [255], dtype=np.uint8),
                             (len(vertices), 1))
        self._trimesh = trimesh
        self.base = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_colors=colors,
                                    process=False)
        self.mesh_k = 1.0  # the scale the estimator's mesh has: base / mesh_k
        mesh = self.base
        self.est = fp.FoundationPose(
            model_pts=mesh.vertices, model_normals=mesh.vertex_normals, mesh=mesh,
            scorer=shared.scorer, refiner=shared.refiner, glctx=shared.glctx,
            debug=options.debug, debug_dir=options.debug_dir)
        self._mesh_file = getattr(self.est, "mesh_path", None)
        self.registered = False  # False: the next frame registers
        self.pose_k = None  # the k of the estimator's remembered pose

    def describe(self):
        size = float((self.base.vertices.max(axis=0) - self.base.vertices.min(axis=0)).max())
        return ("FoundationPose via hitl_foundationpose (mesh {} vertices {} triangles size {!r} m; "
                "register {} / track {} iterations; depth normalised to a 1 m target median)"
                .format(len(self.base.vertices), len(self.base.faces), size,
                        self.opt.register_iterations, self.opt.track_iterations))

    def reset(self):
        self.registered = False

    def close(self):
        self._forget_mesh_file()

    def _forget_mesh_file(self):
        # FoundationPose's reset_object exports every mesh it is given to /tmp/<uuid>.obj and
        # never removes it: at one rebuild per frame that would fill /tmp.
        path = self._mesh_file
        self._mesh_file = None
        if path and os.path.isfile(path):
            try:
                os.unlink(path)
            except OSError:
                pass

    def _scale_mesh(self, k):
        """Gives the estimator the mesh scaled by 1 / k (normals are unchanged by a scale)."""
        b = self.base
        colors = b.visual.vertex_colors if self.opt.mesh_color is not None else None
        mesh = self._trimesh.Trimesh(vertices=b.vertices / k, faces=b.faces,
                                     vertex_normals=b.vertex_normals, vertex_colors=colors,
                                     process=False)
        self._forget_mesh_file()
        self.est.reset_object(model_pts=mesh.vertices, model_normals=mesh.vertex_normals,
                              mesh=mesh)
        self._mesh_file = getattr(self.est, "mesh_path", None)
        self.mesh_k = k

    def frame(self, header, arrays):
        """The `pose` reply to one `frame`, or FrameRefused."""
        seq = header.get("seq")
        if not isinstance(seq, int) or isinstance(seq, bool) or seq < 0:
            raise FrameRefused("frame lacks an unsigned integer `seq`")
        what = "frame {}".format(seq)
        K, (h, w) = _intrinsics(header, what)
        depth = arrays.get("depth")
        if depth is None or depth.dtype != np.dtype("<f4") or depth.shape != (h, w):
            raise FrameRefused("{}: payload `depth` must be <f4 [{},{}]".format(what, h, w))
        mask = arrays.get("mask")
        if mask is None:
            raise FrameRefused(
                "{} has no target mask: the FoundationPose peer needs one on every frame "
                "(registration's ob_mask, and the depth normalisation's median target depth); "
                "send frames from a camera or segmenter that gives a mask".format(what))
        if mask.dtype != np.dtype("u1") or mask.shape != (h, w):
            raise FrameRefused("{}: payload `mask` must be u1 [{},{}]".format(what, h, w))
        color = arrays.get("color")
        if color is None:
            raise FrameRefused("{} has no colour: FoundationPose scores and refines on RGB-D"
                               .format(what))
        if color.dtype != np.dtype("u1") or color.shape != (h, w, 3):
            raise FrameRefused("{}: payload `color` must be u1 [{},{},3]".format(what, h, w))

        z = valid_depth(depth)
        target = mask != 0
        k = normaliser(z, target)
        if k is None:
            self.registered = False
            self.opt.log("{}: no target pixel with depth: lost".format(what))
            return {"type": "pose", "seq": seq, "pose": None, "kind": "lost"}
        if self.opt.rescale_tolerance > 0 and abs(k / self.mesh_k - 1) <= self.opt.rescale_tolerance:
            k = self.mesh_k  # still a similarity: depth and mesh share this k
        if self.registered and k != self.pose_k:
            p = _copy_pose(self.est.pose_last)
            p[..., :3, 3] *= self.pose_k / k
            self.est.pose_last = p
            self.pose_k = k
        if k != self.mesh_k:
            self._scale_mesh(k)

        rgb = np.array(color, dtype=np.uint8)
        depth_n = z / k
        try:
            if self.registered:
                kind = "tracked"
                pose = self.est.track_one(rgb=rgb, depth=depth_n, K=K,
                                          iteration=self.opt.track_iterations)
            else:
                kind = "registered"
                pose = self.est.register(K=K, rgb=rgb, depth=depth_n, ob_mask=target,
                                         iteration=self.opt.register_iterations)
        except Exception as e:  # a CUDA or FoundationPose failure: report it, start over
            self.registered = False
            raise FrameRefused("FoundationPose failed on {} ({}): {}: {}".format(
                what, "track_one" if kind == "tracked" else "register", type(e).__name__, e))
        pose = np.array(pose, dtype=np.float64).reshape(4, 4)
        if not np.isfinite(pose).all() or np.array_equal(pose[:3, :3], np.eye(3)):
            self.registered = False
            self.opt.log("{}: {} gave {}: lost".format(
                what, kind, "a non-finite pose" if not np.isfinite(pose).all()
                else "the identity rotation (no registration)"))
            return {"type": "pose", "seq": seq, "pose": None, "kind": "lost"}
        self.registered = True
        self.pose_k = k
        pose[:3, 3] *= k
        pose[3] = [0.0, 0.0, 0.0, 1.0]
        self.opt.log("{}: {} (k {:.6g})".format(what, kind, k))
        return {"type": "pose", "seq": seq, "pose": [float(x) for x in pose.reshape(-1)],
                "kind": kind}


def _intrinsics(header, what):
    k = header.get("intrinsics")
    if not isinstance(k, dict):
        raise FrameRefused("{} lacks `intrinsics`".format(what))
    try:
        fx, fy, cx, cy = (float(k[n]) for n in ("fx", "fy", "cx", "cy"))
        w, h = k["width"], k["height"]
    except (KeyError, TypeError, ValueError):
        raise FrameRefused("{}: `intrinsics` needs numbers fx, fy, cx, cy, width, height"
                           .format(what))
    if not all(np.isfinite([fx, fy, cx, cy])) or fx <= 0 or fy <= 0:
        raise FrameRefused("{}: intrinsics must be finite with fx, fy > 0".format(what))
    if not (isinstance(w, int) and isinstance(h, int) and w > 0 and h > 0):
        raise FrameRefused("{}: intrinsics width and height must be positive integers"
                           .format(what))
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return K, (h, w)


def stderr_log(prefix):
    def log(msg):
        print("{}: {}".format(prefix, msg), file=sys.stderr, flush=True)
    return log
