"""Vignetting of the micro images, measured on the lenslet image itself.

Every micro image is darker towards its rim (the microlens's own vignetting and the
main-lens pupil's edge); TSPC micro images lose more than half their brightness
before the rim. Corner views sample far from the micro-image centre, and tiles of
neighbouring lenses then differ in brightness: a diamond pattern of tiles. RLC
divides by a white image; a single lenslet frame has none, but averaged over
thousands of lenses the scene cancels out and the micro image's radial profile
remains.

:func:`radial_profile` takes the mean grey level of every lens fully on the sensor at
each distance from its centre (bins of half a pixel); rendering divides each sample
by the profile at
its distance from its lens centre (:func:`plenocal.convert.render.render_view`). The
bin means are smoothed over three bins and divided by their mean over the inner
quarter of the safe disc. Measured rim-to-centre ratios: 0.63 (Boxer), 0.68
(HandTools), 0.94 (Fujita2), ~1 (Boys2, R42 crop).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from plenocal.grid import MicrolensGrid

BIN_PX = 0.5
MAX_LENSES = 3000
FLOOR = 0.15  # smallest profile value divided by (the darkest rim: noise, not signal)


def radial_profile(gray: np.ndarray, grid: MicrolensGrid) -> np.ndarray:
    """Relative brightness at distance ``k * BIN_PX`` from the micro-image centre,
    ``k = 0 ..`` up to ``D / 2 + 1`` (float32, 1 at the centre, >= ``FLOOR``)."""
    D = grid.diameter
    r_max = D / 2 + 1.0
    lenses = np.flatnonzero(grid.inside())
    if len(lenses) == 0:
        return np.ones(int(math.ceil(r_max / BIN_PX)) + 1, dtype=np.float32)
    lenses = lenses[np.linspace(0, len(lenses) - 1, min(MAX_LENSES, len(lenses))).astype(int)]
    r = int(math.ceil(r_max))
    g = np.arange(-r, r + 1, dtype=np.float32)
    dx, dy = np.meshgrid(g, g)
    keep = np.hypot(dx, dy) <= r_max
    dx, dy = dx[keep], dy[keep]
    c = grid.centres[lenses].astype(np.float32)
    mx = np.ascontiguousarray(c[:, :1] + dx[None, :])
    my = np.ascontiguousarray(c[:, 1:] + dy[None, :])
    samples = cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    mean = samples.mean(axis=0)
    rho = np.hypot(dx, dy)
    nbins = int(math.ceil(r_max / BIN_PX)) + 1
    idx = np.minimum(np.rint(rho / BIN_PX).astype(int), nbins - 1)
    total = np.bincount(idx, weights=mean, minlength=nbins)
    count = np.bincount(idx, minlength=nbins)
    prof = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    # empty bins (none at these radii): nearest filled bin; then a 3-bin moving average
    filled = np.flatnonzero(count > 0)
    prof = np.interp(np.arange(nbins), filled, prof[filled])
    prof = np.convolve(np.pad(prof, 1, mode="edge"), np.ones(3) / 3, mode="valid")
    inner = np.arange(nbins) * BIN_PX <= grid.calib.safe_diameter / 8
    ref = float(np.mean(prof[inner])) if inner.any() else float(prof[0])
    if ref <= 0:
        return np.ones(nbins, dtype=np.float32)
    return np.maximum(prof / ref, FLOOR).astype(np.float32)
