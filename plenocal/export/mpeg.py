"""The MPEG-I camera JSON (Version 4.0) read by RVS, DERS, IVDE and TMIV.

Conventions of those tools (TMIV ``Engine_Perspective.hpp`` and ``Quaternion.h``,
RVS ``Parameters.cpp``):

* OMAF axes: x forward, y left, z up, for the world and for every camera. From the
  project's OpenCV axes (x right, y down, z forward): ``x_omaf = z``,
  ``y_omaf = -x``, ``z_omaf = -y`` (:data:`CV_TO_OMAF`), applied to the world frame
  and to each camera frame, so ``R_omaf = A R_cv A^T`` and ``Position = A C``.
* ``Rotation`` = (yaw, pitch, roll) in degrees of the camera-to-world rotation
  ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (TMIV's ``euler2quat`` = q_yaw q_pitch q_roll).
* Perspective projection of a point p in the camera frame:
  ``u = -f_x p_y / p_x + c_x``, ``v = -f_y p_z / p_x + c_y``, with pixel (0, 0)
  covering [0, 1): ``Principle_point`` = OpenCV (cx, cy) + 0.5.
* ``lengthsInMeters: true``; ``Depth_range`` = [near, far] of the 16-bit normalised
  disparity maps (:mod:`plenocal.export.depthmaps`); ``Name`` = ``<cam>_<view>``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from plenocal.camera import PinholeCamera, check_cameras
from plenocal.io.files import write_json
from plenocal.names import flat_key

CV_TO_OMAF = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def ypr_to_matrix(yaw_deg: float, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (camera-to-world, OMAF axes)."""
    y, p, r = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    return _rz(y) @ _ry(p) @ _rx(r)


def matrix_to_ypr(R: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`ypr_to_matrix` (degrees; pitch in [-90, 90]). The pitch by
    ``atan2(-R20, hypot(R00, R10))``, not ``asin(-R20)``: near a view straight up or down
    the arcsine loses the angle's last digits (its slope is infinite there), and the
    matrix read back was 2.5e-9 off at a pitch 1e-6 deg from 90 (a review's find)."""
    R = np.asarray(R, dtype=float)
    cos_pitch = math.hypot(float(R[0, 0]), float(R[1, 0]))
    pitch = math.atan2(float(-R[2, 0]), cos_pitch)
    if cos_pitch < 1e-12:  # gimbal lock: put everything into yaw
        yaw = math.atan2(-R[0, 1], R[1, 1])
        roll = 0.0
    else:
        yaw = math.atan2(R[1, 0], R[0, 0])
        roll = math.atan2(R[2, 1], R[2, 2])
    return math.degrees(yaw), math.degrees(pitch), math.degrees(roll)


def omaf_pose(cam_to_world: np.ndarray) -> tuple[list[float], list[float]]:
    """(Position, Rotation) of an OpenCV camera-to-world pose."""
    A = CV_TO_OMAF
    M = np.asarray(cam_to_world, dtype=float)
    R = A @ M[:3, :3] @ A.T
    C = A @ M[:3, 3]
    return [float(x) for x in C], [float(x) for x in matrix_to_ypr(R)]


def camera_entry(name: str, cam: PinholeCamera, depth_range: tuple[float, float],
                 bit_depth_color: int = 8, bit_depth_depth: int = 16) -> dict:
    """One element of the ``cameras`` list."""
    K = cam.K
    if abs(K[0, 1]) > 1e-9:
        raise ValueError(f"{name}: skewed intrinsics cannot be written as MPEG camera JSON")
    position, rotation = omaf_pose(cam.cam_to_world)
    return {
        "Name": name,
        "Projection": "Perspective",
        "Position": position,
        "Rotation": rotation,
        "Resolution": [int(cam.width), int(cam.height)],
        "Focal": [float(K[0, 0]), float(K[1, 1])],
        "Principle_point": [float(K[0, 2]) + 0.5, float(K[1, 2]) + 0.5],
        "Depth_range": [float(depth_range[0]), float(depth_range[1])],
        "BitDepthColor": int(bit_depth_color),
        "BitDepthDepth": int(bit_depth_depth),
        "ColorSpace": "YUV420",
        "DepthColorSpace": "YUV420",
        "HasInvalidDepth": True,
        "Depthmap": 1,
        "Background": 0,
    }


def mpeg_name(key: str) -> str:
    """``<cam>/<view>`` -> ``<cam>_<view>`` (:func:`plenocal.names.flat_key`)."""
    return flat_key(key)


def mpeg_document(cameras: Mapping[str, PinholeCamera], depth_range: tuple[float, float],
                  content_name: str = "plenocal", bit_depth_color: int = 8) -> dict:
    # a reflection would come out as some other (yaw, pitch, roll) without a word
    check_cameras(cameras, f"MPEG camera parameters of {content_name!r}")
    names = sorted(cameras)
    return {
        "Version": "4.0",
        "Content_name": content_name,
        "BoundingBox_center": [0.0, 0.0, 0.0],
        "Fps": 30,
        "Frames_number": 1,
        "lengthsInMeters": True,
        "sourceCameraNames": [mpeg_name(k) for k in names],
        "cameras": [camera_entry(mpeg_name(k), cameras[k], depth_range, bit_depth_color)
                    for k in names],
    }


#: RVS 4.0's infinity: a far plane of this or more decodes its depth maps with 1/far = 0
#: (image_loading.cpp), and one beyond it is refused (Parameters.cpp)
RVS_MAX_FAR_M = 1000.0


def write_mpeg(path: str | Path, cameras: Mapping[str, PinholeCamera],
               depth_range: tuple[float, float], content_name: str = "plenocal",
               bit_depth_color: int = 8) -> None:
    near, far = depth_range
    if not 0 < near < far:
        raise ValueError(f"depth range must satisfy 0 < near < far (got {near}, {far})")
    if not far < RVS_MAX_FAR_M:
        raise ValueError(f"{path}: depth range far {far} m: RVS reads a far plane of "
                         f"{RVS_MAX_FAR_M:g} m or more as infinity (its depth maps' 1/far "
                         "then 0, not ours) and refuses one beyond; JSON has no infinity: "
                         f"give a far plane under {RVS_MAX_FAR_M:g} m")
    write_json(path, mpeg_document(cameras, depth_range, content_name, bit_depth_color))
