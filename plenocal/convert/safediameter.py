"""The safe micro-image diameter D', measured on the frame (the paper's "safe diameter").

The paper cuts the N x N views inside a disc of diameter ``D'`` around each micro-image
centre, the part of the micro image that carries its own light, and takes
``D' = D - 2`` as a guess (``lens_border`` of the RayCalibData file). Real micro images
do not keep to it: the TSPC frames' micro images overlap their six neighbours (Boys2's
mean micro image, towards a neighbour, is 4 % brighter than between two neighbours at
24 px from the centre, 12 % at 28 px, of a 34 px safe radius), and Raytrix micro images
touch along the lattice directions. A view whose patches are cut where the neighbours'
light arrives mixes two scene points there and shows the lattice (the TSPC corner views'
sawtooth at the paper's q, gone at 0.7 q).

Measure. The light of a micro image itself is radially symmetric about its centre (a
round microlens imaging a round main-lens pupil); its six neighbours' light arrives first
along the six lattice directions. So the six-fold angular variation of the mean micro
image (:func:`mean_polar`: the frame sampled around every lens centre on a polar grid and
averaged over the lenses, scene content averaging out) is the neighbours' share. At
radius ``r`` (:func:`six_fold`): twice the amplitude of its ``cos 6 theta`` component,
peak to peak between the lattice directions and the directions between them, relative to
the micro image's centre brightness. The measured safe radius is the first radius where
it exceeds :data:`WEBER` (2 %, the just visible contrast of a luminance step: the
vignetting correction divides out the radial part of the profile but not this part, which
would show as a lattice of that contrast) and lies :data:`ABOVE_NOISE` standard errors
above zero (each lens's own six-fold component carries its scene; over few lenses their
mean is noise). ``D'`` is twice that radius, never more than the file's
``D - 2 lens_border``.

The measure is one number per camera: rule ``convert_setup`` takes it on the central
array shot (``convert_setup.json``) and every shot's views are cut with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from plenocal.convert.exact import remap
from plenocal.grid import MicrolensGrid

WEBER = 0.02  # six-fold variation (of the centre brightness) that ends the safe disc
ANGLES = 72  # samples per circle
RADIAL_STEP = 0.5  # pixels between the radii measured (linear in between)
MAX_LENSES = 4000  # lenses averaged (an even spread over the sensor)
MIN_LENSES = 50  # fewer whole lenses: no measure, the file's D'
DARK = 0.02  # mean centre brightness (0..1) below which the frame says nothing
ABOVE_NOISE = 3.0  # standard errors the six-fold variation must stand above zero


@dataclass(frozen=True)
class SafeDiameter:
    """The measured safe diameter and how it was found.

    ``diameter_px``: the ``D'`` used (measured, capped by the file's); ``measured_px``:
    twice the first radius where the six-fold variation passes :data:`WEBER` (None where
    the frame gives no measure); ``file_px``: ``D - 2 lens_border``; ``source``:
    ``measured`` or ``file`` (the file's, capped or unmeasured), with ``note`` saying
    why where the frame gave no measure."""

    diameter_px: float
    measured_px: float | None
    file_px: float
    source: str
    note: str = ""

    def to_dict(self) -> dict:
        return {"diameter_px": self.diameter_px, "measured_px": self.measured_px,
                "file_px": self.file_px, "source": self.source, "note": self.note,
                "weber_limit": WEBER}


def polar_samples(gray: np.ndarray, grid: MicrolensGrid, radii: np.ndarray,
                  angles: np.ndarray, max_lenses: int = MAX_LENSES) -> np.ndarray:
    """(lenses, len(radii), len(angles)) the frame ``gray`` (float32, 0..1) sampled at
    polar offsets from the centres (angles from the first lattice direction) of an even
    spread of at most ``max_lenses`` whole lenses."""
    inside = np.flatnonzero(grid.inside(0.0))
    if len(inside) == 0:
        return np.zeros((0, len(radii), len(angles)))
    pick = inside[np.linspace(0, len(inside) - 1, min(max_lenses, len(inside))).astype(int)]
    nb = grid.neighbour_vectors[0]
    theta = angles + math.atan2(nb[1], nb[0])
    dx = (radii[:, None] * np.cos(theta)[None, :]).ravel().astype(np.float32)
    dy = (radii[:, None] * np.sin(theta)[None, :]).ravel().astype(np.float32)
    c = grid.centres[pick].astype(np.float32)
    mx = np.ascontiguousarray(c[:, :1] + dx[None, :])
    my = np.ascontiguousarray(c[:, 1:] + dy[None, :])
    s = remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return s.reshape(len(pick), len(radii), len(angles))


def mean_polar(gray: np.ndarray, grid: MicrolensGrid, radii: np.ndarray,
               angles: np.ndarray, max_lenses: int = MAX_LENSES) -> tuple[np.ndarray, int]:
    """:func:`polar_samples` averaged over the lenses ((len(radii), len(angles))), and
    how many lenses."""
    s = polar_samples(gray, grid, radii, angles, max_lenses)
    if len(s) == 0:
        return np.zeros((len(radii), len(angles))), 0
    return s.mean(axis=0, dtype=np.float64), len(s)


def six_fold(polar: np.ndarray, angles: np.ndarray, order: int = 6) -> np.ndarray:
    """Per radius, the peak-to-peak ``order``-fold variation of ``polar`` (rows: radii)
    around its circle (twice the amplitude of the ``exp(order i theta)`` component)."""
    c = (polar * np.exp(-1j * order * angles)[None, :]).mean(axis=1)
    return 2.0 * 2.0 * np.abs(c)


def measure_safe_diameter(gray: np.ndarray, grid: MicrolensGrid) -> SafeDiameter:
    """The safe diameter ``D'`` of the micro images of ``gray`` (float32 grey, 0..1) on
    ``grid`` (module docstring)."""
    file_d = float(grid.calib.safe_diameter)
    radii = np.arange(0.0, file_d / 2.0 + RADIAL_STEP, RADIAL_STEP)
    angles = np.arange(ANGLES) * (2.0 * math.pi / ANGLES)
    samples = polar_samples(gray, grid, radii, angles)
    used = len(samples)
    if used < MIN_LENSES:
        return SafeDiameter(file_d, None, file_d, "file",
                            f"only {used} whole lenses on the frame (need {MIN_LENSES})")
    polar = samples.mean(axis=0, dtype=np.float64)
    centre = float(polar[0].mean())
    if centre < DARK:
        return SafeDiameter(file_d, None, file_d, "file",
                            f"micro-image centres too dark to measure (mean {centre:.3f})")
    var = six_fold(polar, angles) / centre
    # each lens's six-fold component; their standard error, in the same peak-to-peak units
    cos6 = (np.cos(6.0 * angles) / len(angles)).astype(np.float32)
    sin6 = (np.sin(6.0 * angles) / len(angles)).astype(np.float32)
    spread = np.sqrt((samples @ cos6).var(axis=0, dtype=np.float64)
                     + (samples @ sin6).var(axis=0, dtype=np.float64))  # (radii,)
    noise = 4.0 * spread / math.sqrt(used) / centre
    over = np.flatnonzero((var > WEBER) & (var > ABOVE_NOISE * noise))
    if len(over) == 0:
        return SafeDiameter(file_d, None, file_d, "file",
                            "the micro images hold their own light across the file's D'")
    k = int(over[0])
    if k == 0:
        r = 0.0
    else:  # linear between the last radius under the limit and the first over it
        a, b = var[k - 1], var[k]
        r = float(radii[k - 1] + (WEBER - a) / (b - a) * (radii[k] - radii[k - 1]))
    measured = 2.0 * r
    if measured >= file_d:
        return SafeDiameter(file_d, measured, file_d, "file")
    return SafeDiameter(measured, measured, file_d, "measured")
