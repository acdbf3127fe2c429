"""Synthetic pinhole renders of textured planes, with exact depth: the fixtures of the
depth and view-synthesis tests and of ``bench/bench_depth.py``.

A plane carries a texture image through ``P(a, b) = O + a U + b V`` (texture pixel
(a, b)); a camera sees it through the homography ``K [R U | R V | R O + t]`` (world to
camera ``[R | t]``), so a render is one ``cv2.warpPerspective`` and the depth of each
pixel is the ray-plane intersection.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from plenocal.camera import PinholeCamera, centred_intrinsics, pose


@dataclass(frozen=True)
class TexturedPlane:
    origin: np.ndarray  # world point of texture pixel (0, 0)
    u: np.ndarray  # world step of one texture pixel along a
    v: np.ndarray  # along b
    texture: np.ndarray  # (h, w[, 3]) float32 in [0, 1]

    @property
    def normal(self) -> np.ndarray:
        n = np.cross(self.u, self.v)
        return n / np.linalg.norm(n)


def photo_texture(size: int = 768, seed: int = 0, noise: float = 0.02) -> np.ndarray:
    """A real photograph (scikit-image's astronaut and coffee, tiled) as float RGB."""
    from skimage import data  # noqa: PLC0415

    a = data.astronaut().astype(np.float32) / 255.0
    b = data.coffee().astype(np.float32) / 255.0
    b = cv2.resize(b, (a.shape[1], a.shape[0]), interpolation=cv2.INTER_AREA)
    tex = np.concatenate([a, b], axis=1)
    rng = np.random.default_rng(seed)
    # fine noise so that no window is flat even in the sky of the photo
    tex = np.clip(tex + rng.normal(0, noise, tex.shape).astype(np.float32), 0, 1)
    return cv2.resize(tex, (2 * size, size), interpolation=cv2.INTER_AREA)


def fronto_plane(depth: float, extent: float, texture: np.ndarray,
                 tilt_deg: float = 0.0) -> TexturedPlane:
    """A plane through (0, 0, depth) facing the cameras (normal along -z), optionally
    tilted about the vertical axis by ``tilt_deg``; ``extent`` is its width."""
    h, w = texture.shape[:2]
    s = extent / w
    t = np.radians(tilt_deg)
    u = s * np.array([np.cos(t), 0.0, np.sin(t)])
    v = s * np.array([0.0, 1.0, 0.0])
    origin = np.array([0.0, 0.0, depth]) - u * (w - 1) / 2 - v * (h - 1) / 2
    return TexturedPlane(origin, u, v, texture.astype(np.float32))


def camera_at(centre: np.ndarray, f: float, width: int, height: int) -> PinholeCamera:
    """A camera looking along +z (world = camera axes) at ``centre``."""
    return PinholeCamera(centred_intrinsics(f, width, height),
                         pose(np.eye(3), np.asarray(centre, dtype=float)), width, height)


def render_plane(cam: PinholeCamera, plane: TexturedPlane) -> tuple[np.ndarray, np.ndarray]:
    """(image float32, z-depth float32) of ``plane`` seen by ``cam`` (0 off the plane)."""
    M = cam.world_to_cam
    R, t = M[:3, :3], M[:3, 3]
    H = cam.K @ np.column_stack([R @ plane.u, R @ plane.v, R @ plane.origin + t])
    img = cv2.warpPerspective(plane.texture, H, (cam.width, cam.height), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT,
                              borderValue=0)
    ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    d = cam.rays(np.stack([xs, ys], axis=-1))
    n = plane.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = ((plane.origin - cam.centre) @ n) / (d @ n)  # z-depth (rays have z_cam = 1)
    # inside the textured rectangle?
    X = cam.centre + d * lam[..., None]
    rel = X - plane.origin
    a = rel @ plane.u / (plane.u @ plane.u)
    b = rel @ plane.v / (plane.v @ plane.v)
    h, w = plane.texture.shape[:2]
    inside = (a >= 0) & (a <= w - 1) & (b >= 0) & (b <= h - 1) & (lam > 0)
    depth = np.where(inside, lam, 0.0).astype(np.float32)
    return img.astype(np.float32), depth
