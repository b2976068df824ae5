"""Test peer: OpenCV's robot-world-hand-eye calibration on the observations hitl's solver used.

Reads a JSON file (argv[1]) with the intrinsics and, per view, the flange pose (base -> flange,
4x4), the board pose hitl found (board -> camera, 4x4) and the corners (board xyz, pixel uv).
Prints JSON: OpenCV's Shah solution on hitl's per-view poses ("same_poses"), and on poses from
OpenCV's own solvePnP ("own_pnp"), each as camera_mount (flange -> camera) and board_in_base
(base -> board), 4x4.
"""
import json
import sys

import cv2
import numpy as np


def inv(t):
    r, p = t[:3, :3], t[:3, 3]
    out = np.eye(4)
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ p
    return out


def solve(cam_board, base_flange):
    r_w2c = [t[:3, :3] for t in cam_board]
    t_w2c = [t[:3, 3].reshape(3, 1) for t in cam_board]
    flange_base = [inv(a) for a in base_flange]
    r_b2g = [t[:3, :3] for t in flange_base]
    t_b2g = [t[:3, 3].reshape(3, 1) for t in flange_base]
    r_b2w, t_b2w, r_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(
        r_w2c, t_w2c, r_b2g, t_b2g, method=cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH
    )
    board_base = np.eye(4)
    board_base[:3, :3], board_base[:3, 3] = r_b2w, t_b2w.ravel()
    cam_flange = np.eye(4)
    cam_flange[:3, :3], cam_flange[:3, 3] = r_g2c, t_g2c.ravel()
    return {"camera_mount": inv(cam_flange).tolist(), "board_in_base": inv(board_base).tolist()}


def main():
    data = json.load(open(sys.argv[1]))
    k = data["k"]
    kmat = np.array([[k["fx"], 0, k["cx"]], [0, k["fy"], k["cy"]], [0, 0, 1.0]])
    views = data["views"]
    base_flange = [np.array(v["base_flange"]) for v in views]
    same = solve([inv(np.array(v["board_camera"])) for v in views], base_flange)
    own = []
    for v in views:
        obj = np.array(v["board_points"], dtype=np.float64)
        img = np.array(v["pixels"], dtype=np.float64)
        ok, rvec, tvec = cv2.solvePnP(obj, img, kmat, None, flags=cv2.SOLVEPNP_IPPE)
        assert ok
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, kmat, None, rvec, tvec)
        t = np.eye(4)
        t[:3, :3] = cv2.Rodrigues(rvec)[0]
        t[:3, 3] = tvec.ravel()
        own.append(t)
    print(json.dumps({"opencv": cv2.__version__, "same_poses": same, "own_pnp": solve(own, base_flange)}))


main()
