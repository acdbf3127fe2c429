"""Comparison baseline: OpenCV's StereoSGBM on a rectified pair of views, with its
disparity turned back into z-depth of the first view's (unrectified) camera, so it
can be scored exactly like the plane sweep."""

from __future__ import annotations

import math

import cv2
import numpy as np

from plenocal.camera import PinholeCamera, pose
from plenocal.io.files import to_float, to_uint8
from plenocal.verify.dibr import forward_depth


def _grey8(img: np.ndarray) -> np.ndarray:
    g = to_float(np.asarray(img))
    if g.ndim == 3:
        g = g.mean(axis=2)
    return to_uint8(g)


def sgbm_depth(cam1: PinholeCamera, img1: np.ndarray, cam2: PinholeCamera, img2: np.ndarray,
               near: float, far: float, block: int = 5) -> tuple[np.ndarray, dict]:
    """Z-depth of view 1 from the pair (0 invalid), and facts about the run.

    The pair must be displaced mostly horizontally (SGBM searches along rows)."""
    M = cam2.world_to_cam @ cam1.cam_to_world  # X2 = R X1 + T
    R, T = M[:3, :3], M[:3, 3]
    if abs(T[0]) < abs(T[1]):
        raise ValueError("sgbm_depth needs a horizontally displaced pair of views")
    swap = T[0] > 0  # view 2 left of view 1: rectify (2, 1) instead
    if swap:
        cam1, img1, cam2, img2 = cam2, img2, cam1, img1
        M = cam2.world_to_cam @ cam1.cam_to_world
        R, T = M[:3, :3], M[:3, 3]
    size = (cam1.width, cam1.height)
    zero = np.zeros(5)
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(cam1.K, zero, cam2.K, zero, size, R,
                                                T.reshape(3, 1),
                                                flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1)
    m1 = cv2.initUndistortRectifyMap(cam1.K, zero, R1, P1, size, cv2.CV_32FC1)
    m2 = cv2.initUndistortRectifyMap(cam2.K, zero, R2, P2, size, cv2.CV_32FC1)
    g1 = cv2.remap(_grey8(img1), *m1, cv2.INTER_LINEAR)
    g2 = cv2.remap(_grey8(img2), *m2, cv2.INTER_LINEAR)
    f = P1[0, 0]
    b = float(np.linalg.norm(T))
    dmin = max(0, int(math.floor(f * b / far)) - 1)
    num = int(math.ceil((f * b / near - dmin + 1) / 16.0)) * 16
    sgbm = cv2.StereoSGBM_create(minDisparity=dmin, numDisparities=num, blockSize=block,
                                 P1=8 * block * block, P2=32 * block * block,
                                 disp12MaxDiff=1, uniquenessRatio=10, speckleWindowSize=60,
                                 speckleRange=2, mode=cv2.STEREO_SGBM_MODE_SGBM)
    disp = sgbm.compute(g1, g2).astype(np.float32) / 16.0
    ok = disp > dmin - 0.5
    z_rect = np.where(ok, f * b / np.maximum(disp, 1e-6), 0.0).astype(np.float32)
    # the rectified first camera: same centre, rotated by R1, intrinsics P1
    rect = PinholeCamera(P1[:3, :3].copy(),
                         cam1.cam_to_world @ pose(R1.T, np.zeros(3)), cam1.width, cam1.height)
    depth = forward_depth(rect, z_rect, cam1)
    info = {"num_disparities": num, "min_disparity": dmin, "baseline": b, "focal_rect": f,
            "swapped": bool(swap)}
    if swap:
        # depth of the original first view (now cam2): re-project
        depth = forward_depth(cam1, depth, cam2)
    return depth, info
