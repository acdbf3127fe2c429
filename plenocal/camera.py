"""Pinhole cameras in the project's internal convention.

Convention (DESIGN.md): OpenCV camera axes (x right, y down, z forward), metres,
poses as 4x4 camera-to-world matrices, pixel centres at integer coordinates, so a
point X_c in the camera frame projects to ``K @ X_c / z`` directly. COLMAP puts the
centre of pixel (0, 0) at (0.5, 0.5) and stores cam_from_world: convert only at
that boundary (:func:`k_to_colmap`, :func:`k_from_colmap`). The plain camera file
``cameras.json`` is :mod:`plenocal.artifacts.cameras`.
"""

from __future__ import annotations

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
