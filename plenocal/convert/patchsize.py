"""Per-microlens patch size by block matching against the hexagonal neighbours.

The patch size ``P_i`` of lens ``i`` is the shift of a scene point between
neighbouring micro images, ``P = D / v`` for a point at virtual depth ``v``
(exactly :meth:`plenocal.optics.PlenopticOptics.micro_image_disparity_px`). A
Keplerian relay inverts every micro image, so a point at local offset ``x`` in lens
``i`` lies at ``x + P n`` in the neighbour in direction ``n`` (unit image vector from
``i`` to the neighbour): it moves *towards* the neighbour (the test suite measures
this on chief-ray renders).

Matching. For a candidate ``P`` the block of lens ``i`` centred at ``m_i - (P/2) n``
is compared with the block of the neighbour centred at ``m_j + (P/2) n``: symmetric
about the pair's midpoint, so both blocks stay inside their micro images for
``P`` up to ``D' - 2 r``. The cost is zero-mean normalised cross-correlation (robust
to the vignetting and to the different focus of the lens types), averaged over the
lens's available neighbour pairs. Candidates run over the lens type's virtual-depth
range (``P = D / v``, ``v`` in ``[depth_min, depth_max]``), clipped to
``[min_px, max_fraction D']``, in steps of ``step_px``; the best is refined to
sub-pixel by a parabola. All lenses are matched at once per candidate
(``cv2.remap`` of every block of every lens), never lens by lens.

Confidence in [0, 1]: the best correlation times the peak's distinctness (best
minus the best correlation at least 1.5 px away) times the block's texture
(grey-level standard deviation); zero where the best lies on the edge of the lens
type's range (a better match was cut off). ``search_range: union`` searches every
lens over the union of all types' ranges instead (for multi-focus MLAs whose lens
types also match, blurred, outside their focus range). Lenses below
``min_confidence`` are filled from confident neighbours by an iterative weighted
median over the lattice, then every lens gets ``smooth_iterations`` passes of a
weighted median over itself and its six neighbours (edge-preserving; removes
isolated mismatches).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from plenocal.convert.errors import ConvertError
from plenocal.grid import MicrolensGrid


@dataclass(frozen=True)
class PatchSizeSettings:
    block_radius_px: float | None = None  # None: D' / 7
    block_samples: int = 7  # samples per block side
    step_px: float = 0.5
    min_px: float = 2.0
    max_fraction: float = 0.5  # largest candidate, fraction of D'
    min_confidence: float = 0.25
    smooth_iterations: int = 2
    texture_scale: float = 0.02  # grey std (0..1) at which the texture factor saturates
    search_range: str = "type"  # "type": each lens its type's range; "union": all types'


@dataclass
class PatchSizeResult:
    """Per lens of the grid (grid order): final, raw, confidence and candidate range."""

    patch: np.ndarray  # (n,) float32, filled and smoothed
    raw: np.ndarray  # (n,) best match, NaN where no candidate could be scored
    confidence: np.ndarray  # (n,) in [0, 1]
    confident: np.ndarray  # (n,) bool, confidence >= min_confidence
    lo: np.ndarray  # (n,) candidate range of the lens's type
    hi: np.ndarray
    candidates: np.ndarray  # (c,) candidate patch sizes tried
    warnings: list[str] = field(default_factory=list)


def to_gray(image: np.ndarray) -> np.ndarray:
    """Grey float32 in [0, 1] of a uint8/uint16/float image (RGB or grey)."""
    img = image
    if img.dtype == np.uint8:
        img = img.astype(np.float32) / 255.0
    elif img.dtype == np.uint16:
        img = img.astype(np.float32) / 65535.0
    else:
        img = img.astype(np.float32)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img)


def type_ranges(grid: MicrolensGrid, settings: PatchSizeSettings
                ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Candidate patch-size range [lo, hi] (pixels) of every lens type, ``P = D / v``."""
    c = grid.calib
    D = c.diameter
    cap = settings.max_fraction * c.safe_diameter
    lo_all, hi_all, notes = [], [], []
    for t in c.lens_types:
        if not (math.isfinite(t.depth_min) and math.isfinite(t.depth_max)
                and 0 < t.depth_min < t.depth_max):
            raise ConvertError(f"{c.source}: lens_type[{t.id}]: no usable virtual-depth range "
                               f"({t.depth_min}, {t.depth_max}); the converter needs "
                               "0 < depth_range.min < depth_range.max for every lens type")
        lo, hi = D / t.depth_max, D / t.depth_min
        clo, chi = max(lo, settings.min_px), min(hi, cap)
        if clo > chi:
            notes.append(f"lens type {t.id}: virtual depths {t.depth_min}..{t.depth_max} give "
                         f"patch sizes {lo:.2f}..{hi:.2f} px, outside the searchable "
                         f"{settings.min_px:.2f}..{cap:.2f} px; searching the nearest bound")
            clo = chi = min(max(lo, settings.min_px), cap)
        lo_all.append(clo)
        hi_all.append(chi)
    return np.array(lo_all), np.array(hi_all), notes


def weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Row-wise weighted median of (n, k) arrays (rows with zero weight: NaN)."""
    order = np.argsort(values, axis=1, kind="stable")
    v = np.take_along_axis(values, order, axis=1)
    w = np.take_along_axis(weights, order, axis=1)
    cw = np.cumsum(w, axis=1)
    total = cw[:, -1]
    k = np.argmax(cw >= 0.5 * total[:, None], axis=1)
    out = v[np.arange(len(v)), k]
    return np.where(total > 0, out, np.nan)


def _neighbourhood(values: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """(n, 7): the value of every lens and of its six neighbours (NaN where none)."""
    ext = np.append(values, np.nan)
    return np.concatenate([values[:, None], ext[nb]], axis=1)


def fill_and_smooth(raw: np.ndarray, confidence: np.ndarray, neighbours: np.ndarray,
                    min_confidence: float, smooth_iterations: int, fallback: float
                    ) -> tuple[np.ndarray, list[str]]:
    """Fill low-confidence lenses from confident neighbours, then smooth (weighted
    medians over the lattice). ``fallback``: value for lenses no confident lens reaches."""
    notes: list[str] = []
    n = len(raw)
    w = np.where((confidence >= min_confidence) & np.isfinite(raw), confidence, 0.0)
    P = np.where(w > 0, raw, np.nan)
    if not (w > 0).any():
        notes.append("no lens matched with confidence: the whole map is the fallback "
                     f"{fallback:.3f} px (texture-less image, or calib.xml from another camera)")
        return np.full(n, fallback, dtype=np.float32), notes
    for _ in range(n):
        missing = w <= 0
        if not missing.any():
            break
        vals = _neighbourhood(P, neighbours)[missing, 1:]
        wts = _neighbourhood(w, neighbours)[missing, 1:]
        wts = np.where(np.isfinite(vals), np.nan_to_num(wts), 0.0)
        vals = np.nan_to_num(vals)
        med = weighted_median(vals, wts)
        got = np.isfinite(med)
        if not got.any():
            break
        idx = np.flatnonzero(missing)[got]
        P[idx] = med[got]
        w[idx] = 0.5 * wts[got].max(axis=1)
    if (w <= 0).any():
        k = int((w <= 0).sum())
        notes.append(f"{k} lenses not connected to a confident lens: set to {fallback:.3f} px")
        P[w <= 0] = fallback
        w[w <= 0] = 1e-3
    for _ in range(smooth_iterations):
        vals = _neighbourhood(P, neighbours)
        wts = _neighbourhood(w, neighbours)
        wts[:, 0] *= 2.0
        wts = np.where(np.isfinite(vals), np.nan_to_num(wts), 0.0)
        P = weighted_median(np.nan_to_num(vals), wts)
    return P.astype(np.float32), notes


def _block_offsets(radius: float, samples: int) -> tuple[np.ndarray, np.ndarray]:
    g = np.linspace(-radius, radius, samples)
    bx, by = np.meshgrid(g, g)
    return bx.ravel().astype(np.float32), by.ravel().astype(np.float32)


def match_scores(gray: np.ndarray, grid: MicrolensGrid, candidates: np.ndarray,
                 radius: float, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZNCC of every lens against its neighbours for every candidate patch size.

    Returns (scores (n, c): mean ZNCC over the lens's neighbour pairs, NaN where it has
    none; pairs (n,) number of neighbour pairs; texture (n,) grey std of the block at
    the lens centre)."""
    n = len(grid)
    nb = grid.neighbours
    dirs = grid.neighbour_vectors / grid.diameter  # (6, 2) unit vectors
    bx, by = _block_offsets(radius, samples)
    cx = grid.centres[:, 0].astype(np.float32)[:, None, None]
    cy = grid.centres[:, 1].astype(np.float32)[:, None, None]
    base_x = cx + bx[None, None, :]  # (n, 1, b)
    base_y = cy + by[None, None, :]
    dx = dirs[:, 0].astype(np.float32)[None, :, None]
    dy = dirs[:, 1].astype(np.float32)[None, :, None]
    b = len(bx)
    valid = nb >= 0
    pairs = valid.sum(axis=1)
    safe_nb = np.where(valid, nb, 0)
    opposite = (np.arange(6) + 3) % 6

    def blocks(shift: float, directions: int = 6) -> np.ndarray:
        mx = np.ascontiguousarray(np.broadcast_to(base_x - shift * dx, (n, 6, b))
                                  [:, :directions].reshape(n, -1))
        my = np.ascontiguousarray(np.broadcast_to(base_y - shift * dy, (n, 6, b))
                                  [:, :directions].reshape(n, -1))
        s = cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                      borderValue=0.0)
        return s.reshape(n, directions, b)

    centre_block = blocks(0.0, 1)[:, 0]
    texture = centre_block.std(axis=1)
    scores = np.full((n, len(candidates)), np.nan, dtype=np.float32)
    for ci, P in enumerate(candidates):
        B = blocks(0.5 * float(P))
        B -= B.mean(axis=2, keepdims=True)
        B /= np.sqrt((B * B).sum(axis=2, keepdims=True)) + 1e-6
        total = np.zeros(n, dtype=np.float32)
        for k in range(6):
            partner = B[safe_nb[:, k], opposite[k]]
            total += np.where(valid[:, k], np.einsum("ij,ij->i", B[:, k], partner), 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            scores[:, ci] = np.where(pairs > 0, total / np.maximum(pairs, 1), np.nan)
    return scores, pairs, texture


def estimate_patch_size(image: np.ndarray, grid: MicrolensGrid,
                        settings: PatchSizeSettings | None = None) -> PatchSizeResult:
    """Patch size of every lens of ``grid`` in ``image`` (see the module docstring)."""
    settings = settings or PatchSizeSettings()
    gray = to_gray(image)
    if gray.shape != (grid.height, grid.width):
        raise ConvertError(f"image is {gray.shape[1]}x{gray.shape[0]}, the grid was built for "
                           f"{grid.width}x{grid.height}")
    D_safe = grid.calib.safe_diameter
    radius = settings.block_radius_px or D_safe / 7.0
    t_lo, t_hi, notes = type_ranges(grid, settings)
    step = settings.step_px
    start, stop = float(t_lo.min()), float(t_hi.max())
    count = max(3, int(math.floor((stop - start) / step + 1e-9)) + 1)
    candidates = start + step * np.arange(count)
    if candidates[-1] < stop - 1e-9:
        candidates = np.append(candidates, candidates[-1] + step)
    scores, pairs, texture = match_scores(gray, grid, candidates, radius,
                                          settings.block_samples)

    if settings.search_range not in ("type", "union"):
        raise ConvertError(f"convert.patch_size.search_range: 'type' or 'union', not "
                           f"{settings.search_range!r}")
    if settings.search_range == "union":
        t_lo, t_hi = np.full_like(t_lo, t_lo.min()), np.full_like(t_hi, t_hi.max())
    lo, hi = t_lo[grid.types], t_hi[grid.types]
    # one step of slack beyond the type's range, so that a best match on the range's
    # edge is recognised as such (a best on the slack's edge: cut off, not trusted)
    tol = 1.5 * step + 1e-9
    allowed = (candidates[None, :] >= lo[:, None] - tol) & (candidates[None, :] <= hi[:, None]
                                                            + tol)
    s = np.where(allowed & np.isfinite(scores), scores, -np.inf)
    n = len(grid)
    rows = np.arange(n)
    best = np.argmax(s, axis=1)
    s_best = s[rows, best]
    has = np.isfinite(s_best)
    # sub-pixel: parabola through the best and its two neighbours
    left = s[rows, np.maximum(best - 1, 0)]
    right = s[rows, np.minimum(best + 1, len(candidates) - 1)]
    interior = (best > 0) & (best < len(candidates) - 1) & np.isfinite(left) & np.isfinite(right)
    denom = left - 2 * s_best + right
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.where(interior & (denom < 0), 0.5 * (left - right) / denom, 0.0)
    delta = np.clip(np.nan_to_num(delta), -0.5, 0.5)
    raw = candidates[best] + delta * step
    raw = np.clip(raw, lo - step, hi + step)
    raw = np.where(has, raw, np.nan)
    # confidence: correlation x distinctness x texture
    far = np.abs(candidates[None, :] - candidates[best][:, None]) >= 1.5
    second = np.where(far & np.isfinite(s), s, -np.inf).max(axis=1)
    distinct = np.where(np.isfinite(second), s_best - second, 0.5)
    conf = (np.clip(np.nan_to_num(s_best, neginf=0.0), 0, 1)
            * np.clip(distinct / 0.1, 0, 1)
            * np.clip(texture / settings.texture_scale, 0, 1))
    # a best match on the edge of the lens type's range (not the global edge) is the
    # range cutting off a better match: not trusted, the lens is filled from neighbours
    first = np.argmax(allowed, axis=1)
    last = len(candidates) - 1 - np.argmax(allowed[:, ::-1], axis=1)
    cut = ((best == first) & (first > 0)) | ((best == last) & (last < len(candidates) - 1))
    conf = np.where(has & (pairs >= 2) & ~cut, conf, 0.0).astype(np.float32)
    v_mid = np.sqrt([t.depth_min * min(t.depth_max, 10 * t.depth_min)
                     for t in grid.calib.lens_types])
    fallback = float(np.clip(np.median(grid.diameter / v_mid), t_lo.min(), t_hi.max()))
    patch, more = fill_and_smooth(raw, conf, grid.neighbours, settings.min_confidence,
                                  settings.smooth_iterations, fallback)
    # filled lenses may leave their type's range (a neighbour of another type saw the
    # point in focus); the global candidate range still bounds every value
    patch = np.clip(patch, candidates[0], candidates[-1]).astype(np.float32)
    return PatchSizeResult(
        patch=patch, raw=raw.astype(np.float32), confidence=conf,
        confident=conf >= settings.min_confidence, lo=lo, hi=hi, candidates=candidates,
        warnings=notes + more,
    )
