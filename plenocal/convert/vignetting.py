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

Multi-focus MLAs: the lens types of a Raytrix MLA have different focal lengths and
their micro images fall off differently. At 70 % of the safe radius Boxer's three types
keep 0.76, 0.84 and 0.91 of their centre brightness, Origami's 0.80, 0.94 and 0.87; one
profile for all leaves a corner view's neighbouring tiles (different types) up to 15 %
apart: a mottling of flat areas. :func:`lens_type_profiles` measures one profile per
type, each shrunk towards the profile of all lenses by its own noise (a type's profile
moves away from the common one only as far as the measurement supports: a crop with
200 lenses per type keeps nearly the common profile). TSPC's types agree within 2 %.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from plenocal.convert.exact import remap
from plenocal.grid import MicrolensGrid

BIN_PX = 0.5
MAX_LENSES = 3000
SIGNIFICANCE = 2.0  # standard errors a lens type's profile must differ by to count
FLOOR = 0.15  # smallest profile value divided by (the darkest rim: noise, not signal)


def gains(profiles: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(T, *radius.shape) float64: 1 / each profile row of ``profiles`` ((T, nbins), bins
    every :data:`BIN_PX` px) at the distances ``radius`` from the micro-image centre
    (linear between bins, the end bins beyond): what a sample there is multiplied by to
    undo the vignetting (the render's gain tables, the patch-size matching's blocks)."""
    bins = np.arange(profiles.shape[1]) * BIN_PX
    return np.stack([1.0 / np.interp(radius, bins, p) for p in profiles])


def _normalise(prof: np.ndarray, grid: MicrolensGrid) -> np.ndarray:
    """3-bin moving average, divided by the mean over the inner quarter of the safe disc,
    floored at :data:`FLOOR` (float32)."""
    nbins = len(prof)
    prof = np.convolve(np.pad(prof, 1, mode="edge"), np.ones(3) / 3, mode="valid")
    inner = np.arange(nbins) * BIN_PX <= grid.calib.safe_diameter / 8
    ref = float(np.mean(prof[inner])) if inner.any() else float(prof[0])
    if ref <= 0:
        return np.ones(nbins, dtype=np.float32)
    return np.maximum(prof / ref, FLOOR).astype(np.float32)


def lens_type_profiles(gray: np.ndarray, grid: MicrolensGrid
                       ) -> tuple[np.ndarray, np.ndarray]:
    """One radial profile per lens type (see the module docstring): ``(profiles (T,
    nbins) float32, row (n,) int)``, ``row[i]`` the profile row of lens ``i``; T = 1 for
    single-type MLAs (then the profile is :func:`radial_profile`'s).

    Per type ``t`` and radius bin: ``p_t`` the mean over the type's lenses, ``s_t`` its
    standard error (the lenses' own bin means scatter with the scene), ``p`` the mean over
    all; the type's profile is ``p + (p_t - p) max(0, 1 - (k s_t / d)^2)`` with ``d = p_t -
    p`` and ``k`` = :data:`SIGNIFICANCE` (positive-part James-Stein shrinkage: a
    difference within k standard errors is mostly noise and goes), then normalised like
    :func:`radial_profile`."""
    ids, row = np.unique(grid.types, return_inverse=True)
    if len(ids) == 1:
        return radial_profile(gray, grid)[None, :], np.zeros(len(grid.types), dtype=np.int64)
    D = grid.diameter
    r_max = D / 2 + 1.0
    nbins = int(math.ceil(r_max / BIN_PX)) + 1
    lenses = np.flatnonzero(grid.inside())
    if len(lenses) == 0:
        return np.ones((len(ids), nbins), dtype=np.float32), row
    lenses = lenses[np.linspace(0, len(lenses) - 1,
                                min(MAX_LENSES * len(ids), len(lenses))).astype(int)]
    per_lens, filled = _lens_bins(gray, grid, lenses, r_max, nbins)
    common = per_lens.mean(axis=0)
    profiles = []
    for t in range(len(ids)):
        mine = per_lens[row[lenses] == t]
        if len(mine) < 2:
            profiles.append(common)
            continue
        p_t = mine.mean(axis=0)
        se2 = mine.var(axis=0, ddof=1) / len(mine)
        d2 = (p_t - common) ** 2
        keep = np.clip(1.0 - SIGNIFICANCE ** 2 * se2 / np.maximum(d2, 1e-30), 0.0, 1.0)
        profiles.append(common + (p_t - common) * keep)
    out = []
    for prof in profiles:
        prof = np.interp(np.arange(nbins), filled, prof[filled])
        out.append(_normalise(prof, grid))
    return np.stack(out), row


#: lenses sampled at a time by :func:`_lens_bins`: 256 micro images of 70 px hold 1 M
#: samples (4 MB). All 2,829 of a TSPC frame at once took 140 MB (a float64 copy 93 MB of
#: it) and 0.16-0.25 s, mostly faulting those pages in; by parts 0.05-0.08 s
BINS_CHUNK = 256


def _lens_bins(gray: np.ndarray, grid: MicrolensGrid, lenses: np.ndarray, r_max: float,
               nbins: int) -> tuple[np.ndarray, np.ndarray]:
    """Each lens's mean grey level per radius bin: ((len(lenses), nbins) float64 with
    empty bins 0, indices of the filled bins), :data:`BINS_CHUNK` lenses at a time (each
    lens's sums alone: the same numbers as all at once)."""
    r = int(math.ceil(r_max))
    g = np.arange(-r, r + 1, dtype=np.float32)
    dx, dy = np.meshgrid(g, g)
    keep = np.hypot(dx, dy) <= r_max
    dx, dy = dx[keep], dy[keep]
    idx = np.minimum(np.rint(np.hypot(dx, dy) / BIN_PX).astype(int), nbins - 1)
    order = np.argsort(idx, kind="stable")
    dx, dy, idx = dx[order], dy[order], idx[order]
    c = grid.centres[lenses].astype(np.float32)
    filled, starts, counts = np.unique(idx, return_index=True, return_counts=True)
    out = np.zeros((len(lenses), nbins))
    for a in range(0, len(lenses), BINS_CHUNK):  # a few MB at a time, not the whole set
        part = slice(a, a + BINS_CHUNK)
        mx = np.ascontiguousarray(c[part, :1] + dx[None, :])
        my = np.ascontiguousarray(c[part, 1:] + dy[None, :])
        samples = remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        sums = np.add.reduceat(samples, starts, axis=1, dtype=np.float64)
        out[part, filled] = sums / counts
    return out, filled


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
    samples = remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
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
    return _normalise(prof, grid)
