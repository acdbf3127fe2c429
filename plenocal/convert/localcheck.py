"""Measures that see a converter's local failures, against a reference converter's view
of the same lenslet frame (issue 33).

A whole-view score hides a defect on a small part of the view: the SSIM of a TSPC frame
of a doll on black read 0.949 while the face was a honeycomb. Two measures look locally:

* **Worst textured tile** (:func:`tile_ssim`): our view aligned to the reference
  (:func:`plenocal.convert.compare.alignment`: SIFT + RANSAC affine, the reference's
  pixels are not square), the SSIM map of the grey levels cut into a ``GRID x GRID``
  grid over the overlap, each tile at its best shift: the best whole-pixel shift within
  ``SHIFT_PX`` pixels, or the tile's own sub-pixel shift (phase correlation, within
  ``SUBPIXEL_REACH_PX``), whichever reads higher. One affine map leaves a few pixels of
  local offset: TLCT's views are cut with their own view geometry and pixel aspect, so
  RANSAC's consensus fits one part of the view or another, and a border tile's SSIM
  swung from 0.82 to 0.91 with the draw; Boys2_f150's central view read 0.968 or 0.925
  under two alignments that differ by 2.7 px at a corner (the alignments of two
  versions of the view), and 0.967 and 0.966 with each tile's own sub-pixel shift.
  The lowest tile mean among the tiles where the reference
  has texture (grey-level standard deviation at least ``TEXTURE_STD`` of the full range:
  flat and black tiles say nothing about the conversion). Clean central views read
  0.90-0.96 against TLCT; the doll's honeycomb 0.62.
* **Lattice trace** (:func:`lattice_trace`): how much energy the view holds at the
  spatial frequencies of the microlens lattice, the reciprocal lattice of the tiles
  (first and second shell: the 12 nearest non-zero frequencies). Per frequency, the
  largest power within ``PEAK_BINS`` bins of it over the median power of the ring of
  frequencies of the same magnitude (``RING_WIDTH``), the lattice's own neighbourhoods
  left out: a smooth scene spectrum gives a few dB, a tile lattice, hexagons or a
  sawtooth stands out by ten or more. The mean in dB over the frequencies. Our view is
  measured on the reference's pixel grid (aligned as above, on the same crop), so that
  both views are read at the same frequencies: our lattice is mapped there by the
  alignment's linear part. Its **floor** is the same measure at the lattice's frequencies
  turned by :data:`NULL_TURNS_DEG`, where no lattice is: on the real frames about 4-5 dB,
  scattering by 0.7-1.8 dB from turn to turn, so that a trace within a couple
  of the floor's standard deviations of it (``z``) shows no lattice the measure can see,
  and two such traces differ by noise.

:func:`local_compare` gives both for one view and its reference view.
"""

from __future__ import annotations

import cv2
import numpy as np

from plenocal.convert.compare import alignment, grey, onto_reference
from plenocal.convert.errors import ConvertError

GRID = 6  # tiles per side of the worst-tile grid
#: grey std (0..1) of the reference tile that counts as texture: 1.5 % of full range
#: (3.8 of 255 grey levels), so that a dark subject's texture counts (a doll's hair on
#: black at 2.5 %); at that contrast SSIM still parts a wrong tile from a right one (a
#: tile of no common structure reads at most C2 / (2 var + C2) = 0.67 in its structure
#: term), and a view's noise (1-2 grey levels in TLCT's dark tiles) stays under it. On
#: the nine reference frames of shared/real the tiles between 1.5 and 3 % read 0.97 or
#: more, so the worst tiles there are those of the earlier 3 % (BENCHMARKS.md)
TEXTURE_STD = 0.015
MIN_COVER = 0.8  # share of a tile that the aligned view must cover
PEAK_BINS = 1.5  # radius (FFT bins) searched around each lattice frequency
RING_WIDTH = 0.08  # relative half width of the ring that gives the background power
SHELLS = 12  # lattice frequencies measured (the first two shells of a hexagonal lattice)
#: turns of the lattice's frequencies (degrees) at which :func:`lattice_trace` reads its
#: floor: at least 10 degrees from the hexagonal lattice's own directions (every 60)
NULL_TURNS_DEG = (10, 14, 18, 22, 38, 42, 46, 50)
SHIFT_PX = 2  # each tile's SSIM at its best whole-pixel shift within this many pixels
SUBPIXEL_REACH_PX = 6.0  # or at its own phase-correlation shift, within this many pixels
_C1, _C2 = 0.01 ** 2, 0.03 ** 2  # SSIM's constants for data range 1


def ssim_map(a: np.ndarray, b: np.ndarray, sigma: float = 1.5) -> np.ndarray:
    """SSIM map of two grey float images (Gaussian window ``sigma``, population
    statistics: skimage's ``gaussian_weights=True, use_sample_covariance=False``)."""
    a, b = a.astype(np.float32), b.astype(np.float32)

    def blur(x: np.ndarray) -> np.ndarray:
        return cv2.GaussianBlur(x, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)

    ma, mb = blur(a), blur(b)
    va, vb, cov = blur(a * a) - ma * ma, blur(b * b) - mb * mb, blur(a * b) - ma * mb
    return ((2 * ma * mb + _C1) * (2 * cov + _C2)
            / ((ma * ma + mb * mb + _C1) * (va + vb + _C2)))


def overlap_box(mask: np.ndarray, share: float = 0.98) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1): the rows and columns in which the aligned view covers at least
    ``share`` of the other axis's extent (the overlap's inner rectangle)."""
    rows = np.flatnonzero(mask.mean(axis=1) >= share * mask.mean(axis=1).max())
    cols = np.flatnonzero(mask.mean(axis=0) >= share * mask.mean(axis=0).max())
    if len(rows) < 16 or len(cols) < 16:
        raise ConvertError("the aligned views overlap on too small a rectangle to measure")
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def tile_ssim(ref: np.ndarray, ours: np.ndarray, mask: np.ndarray, grid: int = GRID,
              texture_std: float = TEXTURE_STD) -> dict:
    """SSIM per tile of a ``grid x grid`` grid over the overlap of ``ours`` (aligned onto
    ``ref``'s pixels, grey float) with ``ref``; ``mask`` marks the pixels ``ours``
    covers. Returns the tile SSIMs (NaN where covered less than :data:`MIN_COVER`), which
    tiles are textured, the worst textured tile's SSIM and its index (row, col)."""
    y0, y1, x0, x1 = overlap_box(mask)
    shifts = range(-SHIFT_PX, SHIFT_PX + 1)
    maps = [ssim_map(ref, np.roll(ours, (dy, dx), axis=(0, 1))) for dy in shifts
            for dx in shifts]
    ys = np.linspace(y0, y1, grid + 1).round().astype(int)
    xs = np.linspace(x0, x1, grid + 1).round().astype(int)
    ssim = np.full((grid, grid), np.nan)
    textured = np.zeros((grid, grid), bool)
    for i in range(grid):
        for j in range(grid):
            sl = (slice(ys[i], ys[i + 1]), slice(xs[j], xs[j + 1]))
            m = mask[sl]
            if m.mean() < MIN_COVER:
                continue
            ssim[i, j] = max(max(float(smap[sl][m].mean()) for smap in maps),
                             _subpixel_tile_ssim(ref, ours, sl, m))
            textured[i, j] = float(ref[sl][m].std()) >= texture_std
    pick = np.where(textured & np.isfinite(ssim), ssim, np.inf)
    k = int(np.argmin(pick))
    worst = float(pick.flat[k]) if np.isfinite(pick.flat[k]) else float("nan")
    return {"tiles": ssim, "textured": textured, "worst": worst,
            "worst_tile": (k // grid, k % grid) if np.isfinite(worst) else None,
            "textured_tiles": int(textured.sum())}


def _subpixel_tile_ssim(ref: np.ndarray, ours: np.ndarray, sl: tuple[slice, slice],
                        covered: np.ndarray) -> float:
    """The SSIM of tile ``sl`` with ``ours`` moved by the tile's own shift against
    ``ref`` (:func:`cv2.phaseCorrelate`, Hann window; each axis clipped to
    :data:`SUBPIXEL_REACH_PX`), bicubic, over the tile's ``covered`` pixels. The
    SSIM's window reads the moved image a few pixels past the tile: the tile and a
    margin are moved, not the whole view."""
    a = np.ascontiguousarray(ref[sl], dtype=np.float32)
    b = np.ascontiguousarray(ours[sl], dtype=np.float32)
    window = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(b, a, window)
    r = SUBPIXEL_REACH_PX
    dx, dy = float(np.clip(dx, -r, r)), float(np.clip(dy, -r, r))
    margin = int(np.ceil(r)) + 8
    H, W = ref.shape
    py = slice(max(0, sl[0].start - margin), min(H, sl[0].stop + margin))
    px = slice(max(0, sl[1].start - margin), min(W, sl[1].stop + margin))
    part = np.ascontiguousarray(ours[py, px], dtype=np.float32)
    moved = cv2.warpAffine(part, np.float32([[1, 0, dx], [0, 1, dy]]),
                           (part.shape[1], part.shape[0]), flags=cv2.INTER_CUBIC,
                           borderMode=cv2.BORDER_REFLECT)
    smap = ssim_map(ref[py, px], moved)
    inner = smap[sl[0].start - py.start:sl[0].stop - py.start,
                 sl[1].start - px.start:sl[1].stop - px.start]
    return float(inner[covered].mean())


def lattice_frequencies(basis: np.ndarray, count: int = SHELLS) -> np.ndarray:
    """(count, 2) the ``count`` shortest non-zero frequencies (cycles per pixel, (fx, fy))
    of a lattice whose steps are the rows of ``basis`` (pixels, (x, y))."""
    K = np.linalg.inv(np.asarray(basis, dtype=float).T)  # rows k_i: k_i . b_j = delta_ij
    n = np.arange(-4, 5)
    a, b = np.meshgrid(n, n)
    f = a.reshape(-1, 1) * K[0] + b.reshape(-1, 1) * K[1]
    r = np.linalg.norm(f, axis=1)
    order = np.argsort(np.round(r, 9), kind="stable")
    order = order[r[order] > 0]
    return f[order[:count]]


def turned(basis: np.ndarray, deg: float) -> np.ndarray:
    """The lattice steps ``basis`` (rows, pixels) turned by ``deg`` degrees."""
    a = np.radians(deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return np.asarray(basis, dtype=float) @ rot.T


class _Spectrum:
    """A grey image's Hann-windowed power spectrum (fftshifted) and its frequency grid,
    computed once for every set of frequencies read from it."""

    def __init__(self, img: np.ndarray):
        h, w = img.shape
        win = np.outer(np.hanning(h), np.hanning(w))
        x = (img - img.mean()) * win
        self.power = np.abs(np.fft.fftshift(np.fft.fft2(x))) ** 2
        self.fy = (np.arange(h) - h // 2) / h
        self.fx = (np.arange(w) - w // 2) / w
        self.rad = np.hypot(*np.meshgrid(self.fx, self.fy))
        self.bin_r = np.hypot(1.0 / w, 1.0 / h) / np.sqrt(2.0)  # one bin

    def _box(self, f: np.ndarray, r: float):
        """The rows, the columns and the disc (bool, on their grid) of the bins within
        ``r`` (cycles per pixel) of frequency ``f``; None where no bin is."""
        ys = np.flatnonzero(np.abs(self.fy - f[1]) <= r)
        xs = np.flatnonzero(np.abs(self.fx - f[0]) <= r)
        if not len(ys) or not len(xs):
            return None
        return ys, xs, np.hypot(*np.meshgrid(self.fx[xs] - f[0], self.fy[ys] - f[1])) <= r

    def discs(self, freqs: np.ndarray, radius_bins: float) -> np.ndarray:
        """(h, w) bool: the bins within ``radius_bins`` bins of any of ``freqs``."""
        out = np.zeros(self.power.shape, bool)
        for f in freqs:
            box = self._box(f, radius_bins * self.bin_r)
            if box is not None:
                out[np.ix_(box[0], box[1])] |= box[2]
        return out

    def trace(self, basis: np.ndarray, count: int, avoid: np.ndarray) -> list[float]:
        """Per frequency of the lattice ``basis``: the peak within :data:`PEAK_BINS` bins
        over the median of the ring of its magnitude, in dB; the ring leaves out the bins
        within 3 bins of this lattice's frequencies and of ``avoid`` (more frequencies).
        A shell's frequencies share a magnitude, and its ring's median is taken once."""
        freqs = lattice_frequencies(basis, count)
        near = self.discs(np.concatenate([lattice_frequencies(basis, 60), avoid]), 3.0)
        background: dict[float, float | None] = {}
        values = []
        for f in freqs:
            if abs(f[0]) >= 0.5 or abs(f[1]) >= 0.5:
                continue  # beyond Nyquist on this grid
            box = self._box(f, PEAK_BINS * self.bin_r)
            if box is None or not box[2].any():
                continue
            mag = float(np.hypot(*f))
            if mag not in background:
                ring = (np.abs(self.rad - mag) <= RING_WIDTH * mag) & ~near
                background[mag] = (max(float(np.median(self.power[ring])), 1e-30)
                                   if ring.sum() >= 16 else None)
            if background[mag] is None:
                continue
            peak = self.power[np.ix_(box[0], box[1])][box[2]].max()
            values.append(10.0 * np.log10(peak / background[mag]))
        return values


def lattice_trace(img: np.ndarray, basis: np.ndarray, count: int = SHELLS) -> dict:
    """The lattice's trace in a grey float image ``img`` whose lattice steps are the rows
    of ``basis`` (pixels): mean over the lattice frequencies of the peak power over the
    ring background, in dB, and each frequency's value (module docstring); and its null
    floor (:data:`NULL_TURNS_DEG`): the mean and standard deviation of the same measure
    at the lattice's frequencies turned by each of those angles, where no lattice is.

    The measure on a view without a lattice is not zero: the peak is the largest of a few
    bins of a noisy spectrum, and the scene's own structure lies at some directions more
    than others. On the real frames the floor reads about 4-5 dB, scattering by 0.7-1.8 dB
    between the turns (BENCHMARKS.md, "The lattice measure's floor"), so two views whose
    traces differ by less than that cannot be told apart by it; ``z`` is the trace's
    distance from its floor in floor standard deviations."""
    spec = _Spectrum(np.asarray(img, dtype=np.float64))
    lattice = lattice_frequencies(basis, 60)
    values = spec.trace(basis, count, np.zeros((0, 2)))
    if not values:
        raise ConvertError("no lattice frequency of the view lies below Nyquist")
    null = [float(np.mean(v)) for v in (spec.trace(turned(basis, d), count, lattice)
                                        for d in NULL_TURNS_DEG) if v]
    db = float(np.mean(values))
    m, sd = float(np.mean(null)), float(np.std(null))
    return {"db": db, "per_frequency_db": [float(v) for v in values], "null_db": m,
            "null_sd_db": sd, "z": (db - m) / max(sd, 1e-6)}


def local_compare(ours_img: np.ndarray, ref_img: np.ndarray, basis: np.ndarray) -> dict:
    """Our view (uint8/uint16 RGB or grey) against the reference converter's view of the
    same frame and view position: the worst textured tile (:func:`tile_ssim`) and the
    lattice trace of both views (:func:`lattice_trace`) on the overlap's inner rectangle
    of the reference's grid; ``basis``: our lattice steps in our view's pixels (rows,
    :attr:`plenocal.viewgeom.ViewLayout.basis`)."""
    ours, ref = grey(ours_img), grey(ref_img)
    cv2.setRNGSeed(0)  # RANSAC's draw: the same figures for the same views
    M, inliers = alignment(ours, ref)
    warped, mask = onto_reference(ours, ref.shape, M)
    if mask.mean() < 0.25:
        raise ConvertError(f"the aligned views overlap on {100 * mask.mean():.0f}% only")
    tiles = tile_ssim(ref, warped, mask)
    y0, y1, x0, x1 = overlap_box(mask)
    ref_basis = np.asarray(basis, dtype=float) @ M[:, :2].T  # our lattice on ref's grid
    crop = (slice(y0, y1), slice(x0, x1))
    fill = np.where(mask[crop], warped[crop], float(warped[crop][mask[crop]].mean()))
    ours_trace = lattice_trace(fill, ref_basis)
    ref_trace = lattice_trace(ref[crop], ref_basis)
    return {"worst_tile_ssim": tiles["worst"], "worst_tile": tiles["worst_tile"],
            "textured_tiles": tiles["textured_tiles"], "tile_ssim": tiles["tiles"],
            "lattice_db": ours_trace["db"], "ref_lattice_db": ref_trace["db"],
            "lattice_z": ours_trace["z"], "ref_lattice_z": ref_trace["z"],
            "lattice_null_db": (ours_trace["null_db"], ours_trace["null_sd_db"]),
            "ref_lattice_null_db": (ref_trace["null_db"], ref_trace["null_sd_db"]),
            "inliers": inliers, "alignment": M}

