"""PSNR of a synthesized view against the captured one, excluding a border, in two steps:
the squared errors summed per ring of pixels at the same distance from the image's edge
(:func:`error_rings`, where the view is rendered), then the PSNR for any border from those
sums (:func:`psnr_from_rings`, where the experiment is scored). A change of the border
(config ``verify.psnr_border_px``) then rescores the renders without rendering them again.

Ring ``r`` holds the pixels ``(y, x)`` with ``min(y, x, H - 1 - y, W - 1 - x) = r``; a
border of ``b`` pixels excludes exactly the rings ``r < b``, the pixels that
``img[b:-b, b:-b]`` leaves out (:func:`plenocal.verify.dibr.psnr`).
"""

from __future__ import annotations

import functools

import numba
import numpy as np


@functools.lru_cache(maxsize=8)
def ring_index(height: int, width: int) -> np.ndarray:
    """(H * W,) int64: each pixel's ring, its distance in pixels to the nearest edge, in
    row order (read-only, cached per size)."""
    y = np.arange(height)[:, None]
    x = np.arange(width)[None, :]
    ring = np.minimum(np.minimum(y, height - 1 - y), np.minimum(x, width - 1 - x))
    out = np.ascontiguousarray(ring.ravel(), dtype=np.int64)
    out.flags.writeable = False
    return out


def num_rings(height: int, width: int) -> int:
    """The number of rings of an H x W image: ``(min(H, W) + 1) // 2``."""
    return (min(height, width) + 1) // 2


@numba.njit(cache=True, nogil=True)
def _ring_sums(a, b, rings):  # pragma: no cover - numba
    """Per pixel of two (H, W, C) float images in row order, the squared differences in
    float64 summed over the channels in order and added to the pixel's ring: the bits of
    numpy's ``np.subtract(a, b, dtype=float64)``, squared, summed channel by channel
    and ``np.bincount``-ed (which adds in pixel order), in one pass without temporaries
    (2.1 -> 0.7 ms a 500 x 376 view)."""
    H, W, C = a.shape
    for y in range(H):
        for x in range(W):
            r = min(min(y, H - 1 - y), min(x, W - 1 - x))
            d = np.float64(a[y, x, 0]) - np.float64(b[y, x, 0])
            s = d * d
            for c in range(1, C):
                d = np.float64(a[y, x, c]) - np.float64(b[y, x, c])
                s += d * d
            rings[r] += s


def error_rings(out: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Squared differences of two float images of one shape (H, W) or (H, W, C), in
    float64, summed over the channels and over each ring (:func:`ring_index`, in pixel
    order): (num_rings,) float64."""
    a = np.asarray(out)
    b = np.asarray(truth)
    if a.shape != b.shape:
        raise ValueError(f"PSNR of images of different shapes {a.shape} and {b.shape}")
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    H, W = a.shape[:2]
    rings = np.zeros(num_rings(H, W))
    _ring_sums(np.ascontiguousarray(a), np.ascontiguousarray(b), rings)
    return rings


@functools.lru_cache(maxsize=8)
def _pixels_per_ring(height: int, width: int) -> np.ndarray:
    out = np.bincount(ring_index(height, width), minlength=num_rings(height, width))
    out.flags.writeable = False
    return out


def ring_sizes(shape: tuple[int, ...]) -> np.ndarray:
    """(num_rings,) int64: the values (pixels times channels) of each ring of an image of
    ``shape`` (the pixels counted once per size: every target of a run is scored with
    them)."""
    channels = int(shape[2]) if len(shape) == 3 else 1
    return _pixels_per_ring(int(shape[0]), int(shape[1])) * channels


def psnr_from_rings(sse: np.ndarray, shape: tuple[int, ...], border: int = 0,
                    peak: float = 1.0) -> float:
    """PSNR (dB) from the ring sums ``sse`` (:func:`error_rings`) of an image of
    ``shape``, excluding ``border`` pixels: ``10 log10(peak^2 / MSE)``, the MSE over the
    rings ``r >= border``; inf where it is 0."""
    sse = np.asarray(sse, dtype=np.float64)
    sizes = ring_sizes(tuple(shape))
    if sse.shape != sizes.shape:
        raise ValueError(f"{sse.shape[0]} ring sums for an image of shape {tuple(shape)} "
                         f"({sizes.shape[0]} rings)")
    if not 0 <= border < sizes.shape[0]:
        raise ValueError(f"config: verify.psnr_border_px = {border} leaves no pixel of a "
                         f"{shape[1]} x {shape[0]} view: use 0 to {sizes.shape[0] - 1}")
    mse = float(sse[border:].sum()) / float(sizes[border:].sum())
    return float("inf") if mse == 0 else float(10.0 * np.log10(peak * peak / mse))
