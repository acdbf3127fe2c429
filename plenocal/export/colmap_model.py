"""A COLMAP sparse model of a calibration (cameras.bin, images.bin, points3D.bin, plus
the rigs.bin/frames.bin of COLMAP >= 3.12), loadable by ``pycolmap.Reconstruction``.

One PINHOLE camera per distinct intrinsics (the views of a set share them across
shots), each in a trivial rig of its own (25 rigs for 5 x 5 views), and one image
``<cam>/<view>.png`` per view in a frame of its own with the pose registered (700 frames
on the default data): the images of a camera share its rig. COLMAP stores
cam_from_world and puts the centre of pixel (0, 0) at (0.5, 0.5): the principal point
gets +0.5 (:func:`k_to_colmap`).
No 3-D points are written (the model carries the calibration only).

``pycolmap`` is imported inside the functions: a process must import cv2 first.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from plenocal.camera import PinholeCamera, check_cameras, invert_pose, k_to_colmap


def _intrinsics_key(cam: PinholeCamera) -> tuple:
    K = k_to_colmap(cam.K)
    return (int(cam.width), int(cam.height), round(float(K[0, 0]), 9), round(float(K[1, 1]), 9),
            round(float(K[0, 2]), 9), round(float(K[1, 2]), 9))


def build_reconstruction(cameras: Mapping[str, PinholeCamera], image_ext: str = ".png"):
    """A ``pycolmap.Reconstruction`` holding every camera with its registered pose."""
    import pycolmap  # noqa: PLC0415

    # skew has no PINHOLE equivalent, and a reflection no quaternion
    check_cameras(cameras, "COLMAP model")
    rec = pycolmap.Reconstruction()
    cam_ids: dict[tuple, int] = {}
    for image_id, name in enumerate(sorted(cameras), start=1):
        cam = cameras[name]
        key = _intrinsics_key(cam)
        if key not in cam_ids:
            cam_ids[key] = len(cam_ids) + 1
            K = k_to_colmap(cam.K)
            rec.add_camera_with_trivial_rig(pycolmap.Camera(
                camera_id=cam_ids[key], model="PINHOLE", width=int(cam.width),
                height=int(cam.height), params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))
        M = invert_pose(cam.cam_to_world)
        R = M[:3, :3]
        # re-orthonormalise (composed poses drift by ~1e-16; Rotation3d wants a rotation)
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R), M[:3, 3].copy())
        image = pycolmap.Image(name=f"{name}{image_ext}", camera_id=cam_ids[key],
                               image_id=image_id)
        rec.add_image_with_trivial_frame(image, pose)
    return rec


def write_colmap(folder: str | Path, cameras: Mapping[str, PinholeCamera]) -> None:
    """Write the binary model into ``folder`` (atomic per folder: written into a
    temporary sibling, then renamed)."""
    from plenocal.io.files import atomic_write_dir  # noqa: PLC0415

    rec = build_reconstruction(cameras)
    atomic_write_dir(folder, lambda tmp: rec.write_binary(str(tmp)))
