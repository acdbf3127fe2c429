"""Pinhole cameras in the project's internal convention.

Convention (DESIGN.md): OpenCV camera axes (x right, y down, z forward), metres,
poses as 4x4 camera-to-world matrices, pixel centres at integer coordinates, so a
point X_c in the camera frame projects to ``K @ X_c / z`` directly. COLMAP puts the
centre of pixel (0, 0) at (0.5, 0.5) and stores cam_from_world: convert only at
that boundary (:func:`k_to_colmap`, :func:`k_from_colmap`). The plain camera file
``cameras.json`` is :mod:`plenocal.artifacts.cameras`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PinholeCamera:
    K: np.ndarray  # 3x3
    cam_to_world: np.ndarray  # 4x4
    width: int
    height: int

    @property
    def R(self) -> np.ndarray:
        """Camera-to-world rotation."""
        return self.cam_to_world[:3, :3]

    @property
    def centre(self) -> np.ndarray:
        return self.cam_to_world[:3, 3]

    @property
    def world_to_cam(self) -> np.ndarray:
        return invert_pose(self.cam_to_world)

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (..., 3) to pixels (..., 2) and depths z (...)."""
        Xc = transform(self.world_to_cam, X)
        z = Xc[..., 2]
        uvw = Xc @ self.K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = uvw[..., :2] / uvw[..., 2:3]
        return uv, z

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """World directions (not normalised, z_cam = 1) through pixels (..., 2)."""
        uv1 = np.concatenate([uv, np.ones_like(uv[..., :1])], axis=-1)
        d_cam = uv1 @ np.linalg.inv(self.K).T
        return d_cam @ self.R.T

    def unproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """World points of pixels ``uv`` (..., 2) at z-depth ``depth`` (...)."""
        return self.centre + self.rays(uv) * depth[..., None]

    def to_dict(self) -> dict:
        return {"K": self.K, "cam_to_world": self.cam_to_world, "width": int(self.width),
                "height": int(self.height)}

    @classmethod
    def from_dict(cls, d: dict) -> PinholeCamera:
        return cls(np.asarray(d["K"], dtype=float), np.asarray(d["cam_to_world"], dtype=float),
                   int(d["width"]), int(d["height"]))


#: How far a camera-to-world rotation may stray from orthonormal (``|R^T R - I|``, any entry)
#: and still be written: the workflow's composed poses sit within 1e-11 of it
#: (COLMAP's quaternions, Eq. 6's products); a matrix further off is not a rotation.
ROTATION_TOLERANCE = 1e-6
#: The largest skew (``K[0, 1]``, px) taken as none (COLMAP's PINHOLE and MPEG's cameras have
#: no skew term), and how far the matrices' fixed entries (``K``'s lower triangle and last
#: row, the pose's last row) may stray from theirs
SKEW_TOLERANCE = 1e-9


def camera_problem(cam: PinholeCamera, skew: bool = False) -> str | None:
    """What makes ``cam`` no pinhole camera that the exports can write, or None: a 3x3
    ``K`` of positive, finite focal lengths with no skew (unless ``skew``: the plain
    camera file holds a whole ``K``) and last row (0, 0, 1); a finite
    4x4 ``cam_to_world`` with last row (0, 0, 0, 1) whose rotation is proper (orthonormal
    within :data:`ROTATION_TOLERANCE`, determinant +1: not a reflection); a positive image
    size. MPEG's (yaw, pitch, roll) and COLMAP's quaternion read a reflection as some
    other rotation without a word, so a wrong matrix would otherwise reach every export."""
    K = np.asarray(cam.K, dtype=float)
    M = np.asarray(cam.cam_to_world, dtype=float)
    if K.shape != (3, 3) or M.shape != (4, 4):
        return f"K is {K.shape} and cam_to_world {M.shape}: expected 3x3 and 4x4"
    if not (np.isfinite(K).all() and np.isfinite(M).all()):
        return "K or cam_to_world holds a NaN or an infinity"
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        return f"focal lengths fx {K[0, 0]:g}, fy {K[1, 1]:g} px: both must be positive"
    if max(abs(K[1, 0]), *np.abs(K[2] - [0.0, 0.0, 1.0])) > SKEW_TOLERANCE:
        return "K's lower triangle is not (0, 0, 0) or its last row not (0, 0, 1)"
    if not skew and abs(K[0, 1]) > SKEW_TOLERANCE:
        return (f"skew K[0, 1] = {K[0, 1]:g} px: COLMAP's PINHOLE and MPEG's cameras have no "
                "skew term")
    if np.abs(M[3] - [0.0, 0.0, 0.0, 1.0]).max() > SKEW_TOLERANCE:
        return "cam_to_world's last row is not (0, 0, 0, 1)"
    R = M[:3, :3]
    off = float(np.abs(R.T @ R - np.eye(3)).max())
    if off > ROTATION_TOLERANCE:
        return (f"cam_to_world's rotation is not orthonormal (|R^T R - I| up to {off:.3g}, "
                f"tolerance {ROTATION_TOLERANCE:g}): a scale or shear crept into the pose")
    if np.linalg.det(R) < 0:
        return ("cam_to_world's rotation has determinant -1: a reflection (a flipped axis), "
                "not a rotation")
    if int(cam.width) <= 0 or int(cam.height) <= 0:
        return f"image size {cam.width} x {cam.height}: both must be positive"
    return None


#: The remedy a writer gives for a camera :func:`camera_problem` refuses
WRITE_REMEDY = ("nothing was written: the stage that computed these cameras (named in its "
                "job's log) gave them; report it with that log")


def check_cameras(cameras: Mapping[str, PinholeCamera], where: str,
                  remedy: str = WRITE_REMEDY, skew: bool = False) -> None:
    """Raise a ValueError naming ``where`` (a file), the first camera of ``cameras``
    (name -> :class:`PinholeCamera`, in sorted order) that :func:`camera_problem` finds
    wrong (``skew``: as there), how many are, and ``remedy``."""
    bad = [(k, p) for k in sorted(cameras)
           if (p := camera_problem(cameras[k], skew)) is not None]
    if bad:
        name, problem = bad[0]
        more = f" ({len(bad) - 1} more cameras are wrong too)" if len(bad) > 1 else ""
        raise ValueError(f"{where}: camera {name!r}: {problem}{more}; {remedy}")


def intrinsics(f: float, cx: float, cy: float, fy: float | None = None) -> np.ndarray:
    return np.array([[f, 0.0, cx], [0.0, f if fy is None else fy, cy], [0.0, 0.0, 1.0]])


def downsample_camera(cam: PinholeCamera, factor: int) -> PinholeCamera:
    """The camera of its image reduced ``factor`` times by averaging ``factor x factor``
    blocks (:func:`plenocal.depth.inputs.downsample_image`; ``W // factor x H // factor``).
    Pixel centres sit at integer coordinates, so a reduced pixel x' is centred on the
    full-size ``factor x' + (factor - 1) / 2``: ``f' = f / factor``,
    ``c' = (c + 1/2) / factor - 1/2``."""
    if factor == 1:
        return cam
    K = np.array(cam.K, dtype=np.float64)
    K[0, 0] /= factor
    K[1, 1] /= factor
    K[0, 1] /= factor
    K[0, 2] = (K[0, 2] + 0.5) / factor - 0.5
    K[1, 2] = (K[1, 2] + 0.5) / factor - 0.5
    return PinholeCamera(K, cam.cam_to_world, cam.width // factor, cam.height // factor)


def centred_intrinsics(f: float, width: int, height: int) -> np.ndarray:
    """K with the principal point at the image centre ((W-1)/2, (H-1)/2)."""
    return intrinsics(f, (width - 1) / 2.0, (height - 1) / 2.0)


def pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = t
    return M


def invert_pose(M: np.ndarray) -> np.ndarray:
    R, t = M[:3, :3], M[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def transform(M: np.ndarray, X: np.ndarray) -> np.ndarray:
    return X @ M[:3, :3].T + M[:3, 3]


def k_to_colmap(K: np.ndarray) -> np.ndarray:
    """Internal K (pixel centres at integers) to COLMAP's (centres at +0.5)."""
    out = np.array(K, dtype=float)
    out[0, 2] += 0.5
    out[1, 2] += 0.5
    return out


def k_from_colmap(K: np.ndarray) -> np.ndarray:
    out = np.array(K, dtype=float)
    out[0, 2] -= 0.5
    out[1, 2] -= 0.5
    return out


def rotation_angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees."""
    c = (np.trace(R1.T @ R2) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> tuple[float,
                                                                                 np.ndarray,
                                                                                 np.ndarray]:
    """Similarity (s, R, t) minimising ||dst - (s R src + t)||^2 (Umeyama 1991)."""
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    xs, xd = src - mu_s, dst - mu_d
    cov = xd.T @ xs / len(src)
    U, S, Vt = np.linalg.svd(cov)
    E = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        E[2, 2] = -1
    R = U @ E @ Vt
    var_s = (xs ** 2).sum() / len(src)
    s = float(np.trace(np.diag(S) @ E) / var_s) if with_scale else 1.0
    t = mu_d - s * R @ mu_s
    return s, R, t
