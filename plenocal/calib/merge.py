"""Merge registration A (shots, SfM units) and registration B (views of a set, metres)
into every view of every shot: Eq. 6, ``M_ij = M_i^A M_j^B``.

``M_i^A`` is shot i's central-view camera-to-world pose from registration A with its
translation multiplied by the scale r of Eq. 5 (SfM units -> metres; the paper:
"multiplying the camera position of the central views in registration A by r");
``M_j^B`` is view j's pose relative to the central view (``cam_to_central`` of
``rig.json``). Both are camera-to-world in OpenCV axes, so the product maps view j's
camera frame to the world. The intrinsics are the rig's (focal length from
registration A, principal point per view model).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from plenocal.artifacts.reg_a import RegistrationA
from plenocal.artifacts.rig import RigB
from plenocal.camera import PinholeCamera


def scaled_pose(M: np.ndarray, r: float) -> np.ndarray:
    """M_i^A after scaling: the camera position multiplied by r, rotation kept."""
    out = np.array(M, dtype=float)
    out[:3, 3] *= r
    return out


def merge_cameras(poses_a: Mapping[str, np.ndarray], views_b: Mapping[str, tuple[np.ndarray,
                                                                                  np.ndarray]],
                  r: float, width: int, height: int) -> dict[str, PinholeCamera]:
    """Eq. 6 for every view j of every shot i: ``"<cam>/<view>" -> PinholeCamera``."""
    if not r > 0:
        raise ValueError(f"the scale r must be positive (got {r}); check scale.json")
    out = {}
    for cam in sorted(poses_a):
        MA = scaled_pose(poses_a[cam], r)
        for view in sorted(views_b):
            K, MB = views_b[view]
            out[f"{cam}/{view}"] = PinholeCamera(np.array(K, dtype=float), MA @ MB,
                                                 int(width), int(height))
    return out


def merge_registrations(reg_a: RegistrationA, rig: RigB, r: float, shots: list[str],
                        reg_a_path: str = "reg_a.json", rig_path: str = "rig.json"
                        ) -> dict[str, PinholeCamera]:
    """Eq. 6 for every view of the shots ``shots``: their poses from registration A, the
    rig's views, the scale ``r`` of Eq. 5. Refused, with the file and the remedy, where
    registration A has no pose for a shot or the rig was built with another focal length
    than registration A's (both are written by earlier rules)."""
    missing = [c for c in shots if c not in reg_a.cameras]
    if missing:
        raise ValueError(f"{reg_a_path}: registration A has no pose for {', '.join(missing)}; "
                         "rerun map_a or drop those shots")
    if abs(reg_a.focal_px - rig.focal_px) > 1e-6 * reg_a.focal_px:
        raise ValueError(f"{rig_path} was built with focal length {rig.focal_px} px, "
                         f"registration A now says {reg_a.focal_px} px: rerun rig_b")
    poses = {c: reg_a.poses[c] for c in shots}
    return merge_cameras(poses, rig.view_poses(), r, rig.width, rig.height)
