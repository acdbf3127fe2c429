"""Synthetic lenslet images of a textured fronto-parallel plane, for tests and benchmarks.

Two forward models, both with the micro-image layout of a :class:`MicrolensGrid`:

* :func:`lenslet_from_patch_size` - the plenoptic 2.0 relation alone: sensor pixel
  ``p`` under the lens with micro-image centre ``m`` sees the point ``m - (D/P)(p - m)``
  of a virtual image (a Keplerian relay inverts every micro image), so the same point
  appears in the neighbour lens at direction ``n`` shifted by exactly ``P n`` from
  where it lies in this one: the patch size is ``P`` everywhere. Works for any
  calibration file (no optics needed).
* :func:`lenslet_from_optics` - each pixel's chief ray through its microlens centre
  and the main lens (:meth:`PlenopticOptics.chief_rays`) hits a plane at depth ``Z``;
  the patch size is then whatever the optics give
  (:meth:`PlenopticOptics.micro_image_disparity_px`).

Pixels farther than ``D'/2`` from their lens centre are dark (vignetted rims).
"""

from __future__ import annotations

import cv2
import numpy as np

from plenocal.grid import MicrolensGrid
from plenocal.optics import PlenopticOptics


def random_texture(size: int = 512, sigma: float = 1.5, seed: int = 0) -> np.ndarray:
    """A smooth RGB noise texture in [0, 1] (float32, size x size x 3)."""
    rng = np.random.default_rng(seed)
    base = rng.random((size, size, 3)).astype(np.float32)
    mixed = 0.6 * base + 0.4 * base.mean(axis=2, keepdims=True)
    img = cv2.GaussianBlur(mixed, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    lo, hi = np.percentile(img, 1), np.percentile(img, 99)
    return np.clip((img - lo) / (hi - lo) * 0.8 + 0.1, 0.0, 1.0).astype(np.float32)


def _owner(grid: MicrolensGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every sensor pixel: the nearest lens centre (x, y) and the distance to it."""
    W, H = grid.width, grid.height
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    pix = np.stack([xs, ys], axis=-1)
    ij = (pix - grid.origin) @ np.linalg.inv(grid.A).T
    base = np.floor(ij)
    best = np.full((H, W), np.inf)
    centre = np.zeros((H, W, 2))
    for di in (0, 1):
        for dj in (0, 1):
            c = grid.origin + (base + (di, dj)) @ grid.A.T
            d = ((pix - c) ** 2).sum(axis=-1)
            closer = d < best
            best[closer] = d[closer]
            centre[closer] = c[closer]
    # a hexagonal cell may belong to a lens outside the 2x2 block of its rhombus: check
    # the two remaining lattice neighbours of the rhombus too
    for di, dj in ((1, -1), (-1, 1), (2, -1), (-1, 2)):
        c = grid.origin + (base + (di, dj)) @ grid.A.T
        d = ((pix - c) ** 2).sum(axis=-1)
        closer = d < best
        best[closer] = d[closer]
        centre[closer] = c[closer]
    return pix, centre, np.sqrt(best)


def _sample(texture: np.ndarray, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
    return cv2.remap(texture, tx.astype(np.float32), ty.astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REFLECT)


def _finish(img: np.ndarray, dist: np.ndarray, radius: float) -> np.ndarray:
    rim = np.clip(radius + 0.5 - dist, 0.0, 1.0)[..., None]
    return np.clip(np.rint(img * rim * 255.0), 0, 255).astype(np.uint8)


def lenslet_from_patch_size(grid: MicrolensGrid, patch: float, texture: np.ndarray,
                            texture_scale: float = 1.0, mla: str = "keplerian") -> np.ndarray:
    """uint8 RGB lenslet image whose patch size is ``patch`` pixels at every lens.

    ``texture_scale``: texture pixels per micro-image pixel. ``mla``: ``keplerian``
    (micro images inverted, pixel ``p`` sees ``m - (D/P)(p - m)``) or ``galilean``
    (upright: ``m + (D/P)(p - m)``, a point moves away from the neighbour by ``P``)."""
    if mla not in ("keplerian", "galilean"):
        raise ValueError(f"mla: keplerian or galilean, not {mla!r}")
    pix, m, dist = _owner(grid)
    v = grid.diameter / patch
    sign = -1.0 if mla == "keplerian" else 1.0
    y = m + sign * v * (pix - m)  # the virtual-image point this pixel sees
    t = y / v * texture_scale + np.array(texture.shape[1::-1]) / 2
    img = _sample(texture, t[..., 0], t[..., 1])
    return _finish(img, dist, grid.calib.safe_diameter / 2)


def lenslet_from_optics(grid: MicrolensGrid, optics: PlenopticOptics, depth_m: float,
                        texture: np.ndarray, texel_m: float) -> np.ndarray:
    """uint8 RGB lenslet image of a textured plane at ``depth_m`` (chief rays only).

    ``texel_m``: size of one texture pixel on the plane (metres)."""
    pix, m, dist = _owner(grid)
    o, d = optics.chief_rays(pix, m)
    lam = (depth_m - o[..., 2]) / d[..., 2]
    X = o[..., 0] + lam * d[..., 0]
    Y = o[..., 1] + lam * d[..., 1]
    c = np.array(texture.shape[1::-1]) / 2
    img = _sample(texture, X / texel_m + c[0], Y / texel_m + c[1])
    return _finish(img, dist, grid.calib.safe_diameter / 2)


def calib_for_optics(optics: PlenopticOptics, depth_range: tuple[float, float] = (1.5, 8.0),
                     lens_border: float = 1.0):
    """A one-lens-type RayCalib whose micro-image pitch is the optics' (grid centred)."""
    from plenocal.io.raytrix import LensType, RayCalib  # noqa: PLC0415

    return RayCalib(
        diameter=optics.micro_image_pitch_px, offset=(0.0, 0.0), rotation=0.0,
        lens_border=lens_border, lens_base_x=(1.0, 0.0), lens_base_y=(0.5, 0.8660254037844386),
        lens_types=(LensType(0, (0.0, 0.0), depth_range[0], depth_range[1]),),
    )


def plane_view(calib, layout, patch: float, texture: np.ndarray, r: int, c: int,
               interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
    """The ideal view (r, c) of :func:`lenslet_from_patch_size`'s plane (patch size
    ``patch`` everywhere, ``texture_scale`` 1) on ``layout`` (a
    :class:`plenocal.viewgeom.ViewLayout`): the virtual image read from ``texture`` where
    each output pixel looks, by ``interpolation``; uint8 RGB."""
    ys, xs = np.mgrid[0:layout.height, 0:layout.width].astype(np.float64)
    v = calib.diameter / patch
    d = np.stack([xs - layout.tile_centres[0, 0], ys - layout.tile_centres[0, 1]], -1) * (
        calib.diameter / layout.tile)
    y = layout.lens_centres[0] + d - v * layout.offset_image(r, c)
    t = (y / v + np.array(texture.shape[1::-1]) / 2).astype(np.float32)
    ideal = cv2.remap(texture, t[..., 0], t[..., 1], interpolation)
    return np.clip(np.rint(ideal * 255), 0, 255).astype(np.uint8)
