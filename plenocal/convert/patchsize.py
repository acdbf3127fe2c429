"""Per-microlens patch size by block matching against the hexagonal neighbours.

The patch size ``P_i`` of lens ``i`` is the shift of a scene point between
neighbouring micro images (:meth:`plenocal.optics.PlenopticOptics.micro_image_disparity_px`),
``P = D / v`` for a point at virtual depth ``v`` as the calibration files state it
(:meth:`~plenocal.optics.PlenopticOptics.measured_virtual_depth`; the physical ``a / s``
differs from it by the main lens's convergence). A
Keplerian relay inverts every micro image, so a point at local offset ``x`` in lens
``i`` lies at ``x + P n`` in the neighbour in direction ``n`` (unit image vector from
``i`` to the neighbour): it moves *towards* the neighbour (the test suite measures
this on chief-ray renders). Galilean micro images are upright: ``x - P n``, away from
it. :func:`detect_mla` tells the two apart on the image itself (both ways matched on
the most textured lenses; the real frames separate by 0.6 in mean correlation).

Matching. For a candidate ``P`` the block of lens ``i`` centred at ``m_i + s (P/2) n``
(``s = -1`` Keplerian, ``+1`` Galilean) is compared with the block of the neighbour
centred at ``m_j - s (P/2) n``: symmetric about the pair's midpoint, so both blocks
stay inside their micro images for ``P`` up to ``D' - 2 r``. The cost is zero-mean
normalised cross-correlation (robust to the vignetting and to the different focus of
the lens types), averaged over the lens's available pairs, each weighted by the texture
its blocks carry (:func:`pair_texture`, Eq. M1: a pair that sees only a flat region
correlates its noise as strongly as a textured one its texture): its six neighbours and,
with ``same_type_ring`` on a multi-focus MLA, the six lenses at ``sqrt(3) D`` (the
same lens type, shift ``sqrt(3) P``) where the block fits. With ``aggregate > 0`` the
scores are then aggregated over the lens lattice (:func:`aggregate_scores`: each lens
with its six neighbours, weighted by texture). Both are off by default: on Fujita2
and Origami they moved the confident share by -3..+2 points and left the views as
they were (SSIM to the reference, sharpness, blend disagreement within 0.01), while
the ring costs 0.4-0.9 s per frame and aggregation 0.1 dB on the simulator; what
made the Raytrix frames match is the MLA kind and the union of ranges (confident
share 35 % with each type's own range, 72 % with the union, Fujita2). Candidates run
over the union of the lens types' virtual-depth ranges (``P = D / v``;
``search_range: type`` keeps each lens to its own type's range), clipped to
``[min_px, max_fraction D']``, in steps of ``step_px``; the best is refined to sub-
pixel by a parabola. All lenses are matched at once per candidate
(``cv2.remap`` of every block of every lens), never lens by lens.

Confidence in [0, 1]: the best correlation times the peak's distinctness (best
minus the best correlation at least 1.5 px away) times the block's texture
(grey-level standard deviation); zero where the best lies on the edge of the
searched range, the type's or the whole search's (a better match was cut off; and
where nothing textured is seen the micro images' own structure, their vignetting,
matches best at the smallest candidate, which once filled the face of a doll on black
with 2 px patches on 70 px micro images); where a share of the textured lenses does so
at an end that the file's depth ranges set, a warning names the file
(:func:`range_cut_notes`). Lenses below ``min_confidence`` are
filled by :func:`fill_unreliable`: each from the nearest confident lenses around it (a
weighted median, never a value carried on from lens to lens through a texture-less
region, which drew streaks), within the range the confident lenses span (the scene's
depth range); then every lens gets ``smooth_iterations`` passes of a weighted median
over itself and its six neighbours (edge-preserving; removes isolated mismatches), and
the filled lenses are brought back within that range (:func:`fill_and_smooth`).

Reliability: :func:`reliability` weighs each lens in the blend, 1 where its match was
confident and the map kept it, :data:`UNRELIABLE_WEIGHT` where the size was filled or
the smoothing overrode the match: an estimate nobody measured must not win a blend
against a measured neighbour with a tile many times too large. The blend takes that
weight averaged over the lattice (:func:`lattice_mean`, ``convert.blend.trust_passes``):
with each lens's own, a measured lens among filled ones (ten times their weight) took the
blend over its whole tile, and in the corner views, where every lens samples near its rim,
over its radial weight's whole disc, whose rim drew arcs (issue 33).

Focus (multi-focus MLAs): :func:`focus_weights` gives each lens a weight for the
blend, 1 where its type's depth range covers the virtual depth ``D / P`` it found,
falling off outside, so that views are rendered from the lenses that see sharp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from plenocal.config import stage_defaults
from plenocal.convert.errors import ConvertError
from plenocal.convert.exact import remap
from plenocal.convert.nearest import nearest_within
from plenocal.convert.threads import opencv_threads, run_all
from plenocal.convert.vignetting import gains
from plenocal.grid import MicrolensGrid
from plenocal.viewgeom import mla_sign

_PATCH = stage_defaults("convert.patch_size")


@dataclass(frozen=True)
class PatchSizeSettings:
    """The patch-size estimate's settings; defaults: ``convert.patch_size`` of
    config.schema.yaml."""
    block_radius_px: float | None = _PATCH["block_radius_px"]  # None: D' / 7
    block_samples: int = _PATCH["block_samples"]  # samples per block side
    step_px: float = _PATCH["step_px"]
    min_px: float = _PATCH["min_px"]
    max_fraction: float = _PATCH["max_fraction"]  # largest candidate, fraction of D'
    min_confidence: float = _PATCH["min_confidence"]
    smooth_iterations: int = _PATCH["smooth_iterations"]
    texture_scale: float = _PATCH["texture_scale"]  # grey std (0..1) saturating the texture
    pair_weights: bool = _PATCH["pair_weights"]  # pairs weighted by their texture (Eq. M1)
    search_range: str = _PATCH["search_range"]  # "type": its type's range; "union": all types'
    # measured on Fujita2 / Origami (README): neither changes the views (SSIM, sharpness,
    # blend disagreement within 0.01), aggregation costs the simulator 0.1 dB, the ring
    # 0.4-0.9 s per 4-megapixel frame; both off by default
    aggregate: float = _PATCH["aggregate"]  # weight of each neighbour's costs (the lens's: 2)
    same_type_ring: bool = _PATCH["same_type_ring"]  # the six lenses at sqrt(3) D (multi-focus)
    focus_softness: float = _PATCH["focus_softness"]  # log virtual-depth width of the fall-off
    focus_floor: float = _PATCH["focus_floor"]  # focus weight far outside the type's range


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
    focus: np.ndarray  # (n,) in (0, 1]: how sharp lens i sees its point (its type's range)
    warnings: list[str] = field(default_factory=list)
    # (n, c) float32: each lens's matching score per candidate, -inf outside its allowed
    # range; and the size used where no lens is confident. Kept for the video path's
    # temporal hold (plenocal.convert.video); not written to analysis.npz
    scores: np.ndarray | None = None
    fallback: float | None = None


def to_gray(image: np.ndarray) -> np.ndarray:
    """Grey float32 in [0, 1] of a uint8/uint16/float image (RGB or grey)."""
    img = image
    if img.dtype == np.float32 and img.ndim == 2 and img.flags.c_contiguous:
        return img
    if img.dtype == np.uint8:
        img = np.multiply(img, np.float32(1.0 / 255.0), dtype=np.float32)
    elif img.dtype == np.uint16:
        img = np.multiply(img, np.float32(1.0 / 65535.0), dtype=np.float32)
    elif img.dtype != np.float32:
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
                    centres: np.ndarray, min_confidence: float, smooth_iterations: int,
                    fallback: float) -> tuple[np.ndarray, list[str]]:
    """Fill low-confidence lenses (:func:`fill_unreliable`, ``centres`` in lens pitches),
    then smooth (weighted medians over the lattice), and bring the filled lenses back
    within the range the fill keeps them in (the 2nd-98th percentile of the confident
    sizes): the smoothing let one confident neighbour outweigh a filled lens and its
    filled neighbours, and 1-12 % of the filled lenses of every real frame ended outside
    that range, a darkened HandTools's by up to 14.9 px (34.2 px patches among 16.4-19.3,
    after one match at its type range's top; BENCHMARKS.md, "Filled lenses pulled out of
    the confident range by the smoothing"). A confident lens keeps its own size.
    ``fallback``: the value where no lens is confident."""
    ok, bounds = confident_range(raw, confidence, min_confidence)
    P, w, notes = fill_unreliable(raw, confidence, centres, min_confidence, fallback,
                                  confident=(ok, bounds))
    out = _smooth(P, w, neighbours, smooth_iterations)
    if bounds is not None and not ok.all():
        out = np.where(ok, out, np.clip(out, *bounds)).astype(np.float32)
    return out, notes


def confident_range(raw: np.ndarray, confidence: np.ndarray, min_confidence: float
                    ) -> tuple[np.ndarray, tuple[float, float] | None]:
    """The confident lenses (``raw`` (n,) matched sizes, ``confidence`` (n,)): (n,) bool,
    and the :data:`FILL_PERCENTILES` of their sizes, the range a filled lens is kept in
    (None where no lens is confident)."""
    ok = (confidence >= min_confidence) & np.isfinite(raw)
    if not ok.any():
        return ok, None
    lo, hi = np.percentile(raw[ok], FILL_PERCENTILES)
    return ok, (float(lo), float(hi))


def _smooth(P: np.ndarray, w: np.ndarray, neighbours: np.ndarray, iterations: int
            ) -> np.ndarray:
    """``iterations`` passes of a weighted median over each lens and its six neighbours
    (the lens's own weight doubled), float32."""
    for _ in range(iterations):
        vals = _neighbourhood(P, neighbours)
        wts = _neighbourhood(w, neighbours)
        wts[:, 0] *= 2.0
        wts = np.where(np.isfinite(vals), np.nan_to_num(wts), 0.0)
        P = weighted_median(np.nan_to_num(vals), wts)
    return np.asarray(P, dtype=np.float32)


#: blend weight of a lens whose patch size was not measured (filled, or overridden by the
#: smoothing) against 1 for a measured one: a tenth, so that any measured lens covering
#: the pixel decides it
UNRELIABLE_WEIGHT = 0.1
FILL_NEIGHBOURS = 12  # confident lenses a filled lens takes its size from (two rings)
FILL_REACH = 24.0  # lens pitches: farther confident lenses do not fill (the scene's median)
#: the range of the confident sizes a filled lens is kept in, before and after the smoothing
FILL_PERCENTILES = (2.0, 98.0)


def fill_unreliable(raw: np.ndarray, confidence: np.ndarray, centres: np.ndarray,
                    min_confidence: float, fallback: float,
                    confident: tuple[np.ndarray, tuple[float, float] | None] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Patch sizes with every unconfident lens filled (module docstring).

    ``centres``: (n, 2) lens centres in lens pitches. A lens below ``min_confidence``
    takes the weighted median (weights: confidence over squared distance) of the
    :data:`FILL_NEIGHBOURS` nearest confident lenses within :data:`FILL_REACH` pitches,
    found in one pass (filled values never fill others), clipped to the 2nd-98th
    percentile of the confident sizes; where none is that near, the confident median;
    where no lens is confident, ``fallback``. Returns (sizes, weights for the
    smoothing: the confidence, a tenth of the neighbours' mean for filled lenses, notes).
    ``confident``: :func:`confident_range` of these arguments where the caller has it."""
    notes: list[str] = []
    n = len(raw)
    ok, bounds = confident or confident_range(raw, confidence, min_confidence)
    if bounds is None:
        notes.append("no lens matched with confidence: the whole map is the fallback "
                     f"{fallback:.3f} px (texture-less image, or calib.xml from another camera)")
        return np.full(n, fallback), np.full(n, 1e-3), notes
    good = raw[ok]
    lo, hi = bounds
    P = np.where(ok, raw, np.nan)
    w = np.where(ok, confidence, 0.0)
    missing = np.flatnonzero(~ok)
    if len(missing):
        k = min(FILL_NEIGHBOURS, int(ok.sum()))
        dist, idx = nearest_within(centres[ok], centres[missing], k, FILL_REACH)
        found = idx < len(good)
        safe = np.where(found, idx, 0)
        wts = np.where(found, confidence[ok][safe] / np.maximum(dist, 0.5) ** 2, 0.0)
        med = weighted_median(good[safe], wts)
        far = ~np.isfinite(med)
        med[far] = float(np.median(good))
        P[missing] = np.clip(med, lo, hi)
        w[missing] = 0.1 * np.where(found, confidence[ok][safe], 0.0).sum(axis=1) / k + 1e-3
        if far.any():
            notes.append(f"{int(far.sum())} lenses farther than {FILL_REACH:g} lens pitches "
                         f"from any confident lens: set to the confident median "
                         f"{float(np.median(good)):.3f} px")
    return P, w, notes


def reliability(raw: np.ndarray, patch: np.ndarray, confident: np.ndarray,
                step_px: float) -> np.ndarray:
    """Each lens's weight in the blend: 1 where its size was measured with confidence and
    the map kept it (within two candidate steps of the match), else
    :data:`UNRELIABLE_WEIGHT` (float32)."""
    kept = confident & np.isfinite(raw) & (np.abs(patch - np.nan_to_num(raw)) <= 2 * step_px)
    return np.where(kept, 1.0, UNRELIABLE_WEIGHT).astype(np.float32)


def lattice_mean(values: np.ndarray, neighbours: np.ndarray, passes: int) -> np.ndarray:
    """``passes`` rounds of the mean of each lens's value (``values`` (n,)) and its
    neighbours' (``neighbours`` (n, 6), -1 where a lens has none: the mean of those it
    has), float32. On the real frames one pass brought the largest ratio of two adjacent
    lenses' weights of :func:`reliability` from 10 to 5.5, two passes to 2.6."""
    v = np.asarray(values, dtype=np.float32)
    nb = np.asarray(neighbours)
    have = nb >= 0
    count = np.float32(1.0) + have.sum(axis=1, dtype=np.float32)
    for _ in range(passes):
        v = (v + np.where(have, v[np.maximum(nb, 0)], np.float32(0.0)).sum(axis=1)) / count
    return v.astype(np.float32)


def out_of_range(result: PatchSizeResult) -> np.ndarray:
    """(n,) bool: lenses whose best match lay on an end of the whole search (the smallest
    or the largest candidate): their patch size lies beyond what was searched (an
    out-of-focus background past the lens types' depth ranges) or the micro images' own
    structure matched (nothing to match), and the filled size is a guess at its scale."""
    c = result.candidates
    raw = result.raw
    with np.errstate(invalid="ignore"):
        return np.isfinite(raw) & ((raw <= c[0] + 1e-6) | (raw >= c[-1] - 1e-6))


def _block_offsets(radius: float, samples: int) -> tuple[np.ndarray, np.ndarray]:
    g = np.linspace(-radius, radius, samples)
    bx, by = np.meshgrid(g, g)
    return bx.ravel().astype(np.float32), by.ravel().astype(np.float32)


Vignetting = tuple[np.ndarray, np.ndarray]  # (profiles (T, nbins), row (n,)) per lens type


def block_gains(profiles: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """(T, *dx.shape) float32: 1 / the radial profile of each lens type (``profiles``
    (T, nbins): :func:`plenocal.convert.vignetting.gains`) at the offsets
    ``(dx, dy)`` from the micro-image centre.

    Matching divides the blocks by it. Where the micro images darken towards their rim,
    a block placed ``P / 2`` out from the centre carries the fall-off as a ramp, and its
    partner in the neighbour carries the opposite ramp; the ramps correlate negatively,
    more so the larger the candidate ``P``, and pull a weakly textured lens's best match
    towards smaller sizes (the simulator's near objects: 8.43 px read as 7.80 px at a
    tenth of the texture's contrast; with the profile divided out, 8.38)."""
    return gains(profiles, np.hypot(dx, dy).astype(np.float64)).astype(np.float32)


RING2 = np.array([(1, 1), (-1, 2), (-2, 1), (-1, -1), (1, -2), (2, -1)], dtype=np.int64)


#: a pair's weight where both its blocks are flat (Eq. M1): a lens with no textured pair
#: keeps the plain mean of its pairs, as without the weights (its confidence is nil anyway)
FLAT_PAIR_WEIGHT = 1e-3


def texture_share(std: np.ndarray, texture_scale: float) -> np.ndarray:
    """How textured a block is, in [0, 1]: its grey-level standard deviation ``std`` over
    ``texture_scale``, saturating at 1 (the confidence's texture factor, and Eq. M1's)."""
    return np.clip(std / texture_scale, 0, 1)


def pair_texture(std: np.ndarray, texture_scale: float | None) -> np.ndarray:
    """Eq. M1: a block's weight in the pairs it belongs to, ``min(1, s / s0) + eps`` for
    its grey-level standard deviation ``s`` (0..1 grey, after the vignetting is divided
    out) and ``s0 = texture_scale`` (``eps``: :data:`FLAT_PAIR_WEIGHT`). A pair weighs
    the smaller of its two blocks' weights, at the candidate where that is smallest, over
    the largest such weight among the lens's pairs (:func:`match_scores`).

    ZNCC normalises the contrast away, so a pair of flat blocks (a black background, an
    overexposed wall) correlates their noise and faint remnants of structure as strongly
    as a textured pair its texture: on a lens whose lower neighbours see only black, those
    pairs' chance peak outvoted the pairs that see the edge above (Boxer's board:
    BENCHMARKS.md, "Pairs that see nothing"). None: 1 for every block."""
    if texture_scale is None:
        return np.ones_like(std)
    return texture_share(std, texture_scale) + FLAT_PAIR_WEIGHT


def pair_weights(texture: np.ndarray) -> np.ndarray:
    """(n, pairs) float32: each pair's weight in its lens's score, from ``texture`` (n,
    pairs, candidates): the pair's :func:`pair_texture` per candidate, NaN where it was
    not scored. A pair weighs its texture at the candidate where it is flattest, the same
    at every candidate (weights that changed with the candidate would let a size win by
    leaving out a pair that disagrees with it), relative to the lens's most textured pair
    (where all are alike, a weakly textured surface or nothing at all, they weigh alike,
    as without the weights); 0 for a pair never scored."""
    weight = np.where(np.isfinite(texture), texture, np.inf).min(axis=2)
    weight = np.where(np.isfinite(weight), weight, 0.0).astype(np.float32)
    top = weight.max(axis=1, keepdims=True)  # 0 only where every weight of the lens is 0
    return weight / np.where(top > 0, top, np.float32(1.0))


def _ring_neighbours(grid: MicrolensGrid, steps: np.ndarray) -> np.ndarray:
    """(n, 6) index of the lens at each lattice step (``steps`` (6, 2)) or -1."""
    lo = grid.ij.min(axis=0)
    shape = grid.ij.max(axis=0) - lo + 5
    table = np.full(tuple(shape), -1, dtype=np.int64)
    local = grid.ij - lo + 2
    table[local[:, 0], local[:, 1]] = np.arange(len(grid.ij))
    nb = np.full((len(grid.ij), len(steps)), -1, dtype=np.int64)
    for k, step in enumerate(steps):
        q = local + step
        ok = (q[:, 0] >= 0) & (q[:, 0] < shape[0]) & (q[:, 1] >= 0) & (q[:, 1] < shape[1])
        nb[ok, k] = table[q[ok, 0], q[ok, 1]]
    return nb


#: lenses whose block maps (and squared blocks) :func:`match_scores` makes at a time: on
#: a 41-MP sensor (34,684 lenses) the maps of all of them took 0.2 GB a thread, and the
#: squares 0.1 GB; each lens's numbers are its own, the same by chunks
LENS_CHUNK = 4096


def _lens_chunks(n: int) -> list[slice]:
    """Slices of :data:`LENS_CHUNK` lenses covering ``range(n)``."""
    return [slice(a, min(a + LENS_CHUNK, n)) for a in range(0, n, LENS_CHUNK)]


def match_scores(gray: np.ndarray, grid: MicrolensGrid, candidates: np.ndarray,
                 radius: float, samples: int, sign: float = -1.0, ring2: bool = False,
                 threads: int = 1, vignetting: Vignetting | None = None,
                 texture_scale: float | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZNCC of every lens against its neighbours for every candidate patch size.

    ``sign``: -1 Keplerian (a point moves towards the neighbour by ``P``), +1 Galilean
    (away from it). ``ring2``: also the six lenses at ``sqrt(3) D`` (shift ``sqrt(3) P``),
    where a block fits. ``vignetting``: the micro images' radial profiles (profiles (T,
    nbins), row (n,): :func:`plenocal.convert.vignetting.lens_type_profiles`); each
    block sample is divided by its lens's profile at the sample's distance from the lens
    centre (:func:`block_gains`), None for none. ``texture_scale``: each pair's ZNCC is
    weighted by the texture of its flatter block where that is flattest over the
    candidates, relative to the lens's most textured pair (:func:`pair_texture`, Eq.
    M1); None: every pair weighs the same. Returns (scores (n, c): the pairs' weighted
    mean ZNCC, NaN where the lens has none; pairs (n,) number of nearest-neighbour pairs;
    texture (n,) grey std of the block at the lens centre)."""
    n = len(grid)
    rings = [(grid.neighbours, grid.neighbour_vectors / grid.diameter, 1.0)]
    if ring2:
        v2 = RING2 @ grid.A.T
        rings.append((_ring_neighbours(grid, RING2), v2 / np.linalg.norm(v2, axis=1)[:, None],
                      math.sqrt(3.0)))
    bx, by = _block_offsets(radius, samples)
    cx = grid.centres[:, 0].astype(np.float32)[:, None, None]
    cy = grid.centres[:, 1].astype(np.float32)[:, None, None]
    base_x = cx + bx[None, None, :]  # (n, 1, b)
    base_y = cy + by[None, None, :]
    b = len(bx)
    opposite = (np.arange(6) + 3) % 6
    half_safe = grid.calib.safe_diameter / 2

    def blocks(shift: float, dirs: np.ndarray) -> np.ndarray:
        k = len(dirs)
        dx = dirs[:, 0].astype(np.float32)[None, :, None]
        dy = dirs[:, 1].astype(np.float32)[None, :, None]
        s = np.empty((n, k, b), np.float32)
        for z in _lens_chunks(n):  # the maps of a chunk of lenses at a time
            m = z.stop - z.start
            mx = np.ascontiguousarray(np.broadcast_to(base_x[z] + sign * shift * dx, (m, k, b))
                                      .reshape(m, -1))
            my = np.ascontiguousarray(np.broadcast_to(base_y[z] + sign * shift * dy, (m, k, b))
                                      .reshape(m, -1))
            s[z] = remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0.0).reshape(m, k, b)
        if vignetting is not None:
            gain = block_gains(vignetting[0], bx[None, :] + sign * shift * dirs[:, :1],
                               by[None, :] + sign * shift * dirs[:, 1:])
            s *= gain[0] if len(gain) == 1 else gain[vignetting[1]]
        return s

    centre_block = blocks(0.0, np.zeros((1, 2)))[:, 0]
    texture = centre_block.std(axis=1)
    pairs = (grid.neighbours >= 0).sum(axis=1)
    c = len(candidates)
    # every pair's ZNCC and texture (its flatter block's, Eq. M1) per candidate; NaN where
    # the pair has no partner or its blocks leave the safe micro image
    corr = np.full((n, 6 * len(rings), c), np.nan, dtype=np.float32)
    tex = np.full((n, 6 * len(rings), c), np.nan, dtype=np.float32)

    def score(ci: int) -> None:  # one candidate size: its own column, alone
        P = candidates[ci]
        for r, (nb, dirs, scale) in enumerate(rings):
            shift = 0.5 * scale * float(P)
            if shift + radius > half_safe:
                continue
            B = blocks(shift, dirs)
            B -= B.mean(axis=2, keepdims=True)
            norm = np.empty(B.shape[:2], np.float32)
            for z in _lens_chunks(n):  # each lens's sum alone: the same numbers by chunks
                np.sqrt((B[z] * B[z]).sum(axis=2), out=norm[z])
            B /= norm[:, :, None] + 1e-6
            t = pair_texture(norm / math.sqrt(b), texture_scale)
            valid = nb >= 0
            safe_nb = np.where(valid, nb, 0)
            for k in range(6):
                partner = B[safe_nb[:, k], opposite[k]]
                corr[:, 6 * r + k, ci] = np.where(valid[:, k],
                                                  np.einsum("ij,ij->i", B[:, k], partner),
                                                  np.nan)
                tex[:, 6 * r + k, ci] = np.where(
                    valid[:, k], np.minimum(t[:, k], t[safe_nb[:, k], opposite[k]]), np.nan)

    with opencv_threads(1 if threads > 1 else None):
        run_all(score, list(range(c)), threads)
    weight = pair_weights(tex)
    ok = np.isfinite(corr)
    w = np.where(ok, weight[:, :, None], 0.0)
    num = (w * np.where(ok, corr, 0.0)).sum(axis=1)
    den = w.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        scores = np.where(den > 0, num / den, np.nan).astype(np.float32)
    return scores, pairs, texture


def detect_mla(gray: np.ndarray, grid: MicrolensGrid, radius: float, samples: int,
               candidates: np.ndarray, max_lenses: int = 600, threads: int = 1
               ) -> tuple[str, float, float]:
    """Which way points move between neighbouring micro images, read from the image.

    Matches an even spread of textured lenses (at most ``max_lenses``) against their
    six neighbours both ways: towards the neighbour (Keplerian: micro images inverted)
    and away from it (Galilean: upright), the two ways side by side on ``threads``
    threads (each computed alone: the same numbers with any number). Returns (kind, mean
    best ZNCC towards, mean best ZNCC away); the kind whose best match is higher.
    Deterministic (no sampling)."""
    inside = np.flatnonzero(grid.inside() & (grid.neighbours >= 0).all(axis=1))
    if len(inside) == 0:
        return "keplerian", float("nan"), float("nan")
    bx, by = _block_offsets(radius, samples)
    blk = np.stack([bx, by], axis=1)[None, :, :]

    def sample(pts: np.ndarray) -> np.ndarray:
        m = pts.reshape(pts.shape[0], -1, 2).astype(np.float32)
        v = remap(gray, np.ascontiguousarray(m[..., 0]), np.ascontiguousarray(m[..., 1]),
                      cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return v.reshape(pts.shape[:-1])

    centre = sample(grid.centres[inside][:, None, :] + blk)
    tex = centre.std(axis=1)
    order = np.argsort(-tex, kind="stable")[: max(1, len(inside) // 3)]
    chosen = np.sort(inside[order])
    chosen = chosen[np.linspace(0, len(chosen) - 1, min(max_lenses, len(chosen))).astype(int)]
    dirs = grid.neighbour_vectors / grid.diameter
    nb = grid.neighbours[chosen]
    m_i = grid.centres[chosen]
    half_safe = grid.calib.safe_diameter / 2
    best = {}

    def match(way: tuple[str, float]) -> None:  # one way: its own entry of best, alone
        kind, sign = way
        curve = []
        for P in candidates:
            sh = 0.5 * float(P)
            if sh + radius > half_safe:
                break
            total = np.zeros(len(chosen))
            for k in range(6):
                a = sample(m_i[:, None, :] + sign * sh * dirs[k] + blk)
                b = sample(grid.centres[nb[:, k]][:, None, :] - sign * sh * dirs[k] + blk)
                a = a - a.mean(axis=1, keepdims=True)
                b = b - b.mean(axis=1, keepdims=True)
                den = np.sqrt((a * a).sum(axis=1) * (b * b).sum(axis=1)) + 1e-9
                total += (a * b).sum(axis=1) / den
            curve.append(total / 6)
        best[kind] = float(np.mean(np.max(np.stack(curve, axis=1), axis=1))) if curve else 0.0

    with opencv_threads(1 if threads > 1 else None):
        run_all(match, [("keplerian", -1.0), ("galilean", 1.0)], threads)
    kind = "keplerian" if best["keplerian"] >= best["galilean"] else "galilean"
    return kind, best["keplerian"], best["galilean"]


def detect_mla_kind(gray: np.ndarray, grid: MicrolensGrid, settings: PatchSizeSettings,
                    threads: int = 1) -> tuple[str, float, float]:
    """:func:`detect_mla` with the settings' block and a coarse candidate range (up to
    the largest searchable patch size, ``D' / 40`` steps), on ``threads`` threads."""
    D_safe = grid.calib.safe_diameter
    radius = settings.block_radius_px or D_safe / 7.0
    cap = settings.max_fraction * D_safe
    cand = np.arange(settings.min_px, cap + 1e-9, max(settings.step_px, D_safe / 40))
    return detect_mla(gray, grid, radius, settings.block_samples, cand, max_lenses=200,
                      threads=threads)


def aggregate_scores(scores: np.ndarray, weight: np.ndarray, neighbours: np.ndarray,
                     neighbour_weight: float) -> np.ndarray:
    """Cost aggregation over the lens lattice: each lens's scores averaged with its six
    neighbours' (weights: ``2 w_i`` for itself, ``neighbour_weight w_j`` for each
    neighbour), so that one lens's ambiguous or defocused match is decided by the
    surface around it. NaN scores take no weight."""
    if neighbour_weight <= 0:
        return scores
    ok = np.isfinite(scores)
    w = weight[:, None] * ok
    sw = np.where(ok, scores, 0.0) * w
    num = 2.0 * sw
    den = 2.0 * w
    valid = neighbours >= 0
    safe = np.where(valid, neighbours, 0)
    for k in range(neighbours.shape[1]):
        m = valid[:, k][:, None] * neighbour_weight
        num = num + m * sw[safe[:, k]]
        den = den + m * w[safe[:, k]]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan).astype(np.float32)


def focus_weights(grid: MicrolensGrid, patch: np.ndarray, softness: float, floor: float
                  ) -> np.ndarray:
    """How sharp each lens sees its point: 1 where its virtual depth ``v = D / P`` lies in
    its lens type's depth range, falling off as ``exp(-(d / softness)^2)`` with the
    distance ``d`` of ``log v`` from the range, never below ``floor``. One lens type (or
    types whose ranges all cover the point): 1 everywhere."""
    c = grid.calib
    v = np.log(grid.diameter / np.maximum(patch, 1e-6))
    lo = np.log([t.depth_min for t in c.lens_types])[grid.types]
    hi = np.log([t.depth_max for t in c.lens_types])[grid.types]
    d = np.maximum(lo - v, 0.0) + np.maximum(v - hi, 0.0)
    return np.maximum(np.exp(-(d / softness) ** 2), floor).astype(np.float32)


#: a warning when at least this share of the textured lenses (and :data:`RANGE_CUT_MIN`
#: of them) matched best at an end of the search that the file's depth ranges set
RANGE_CUT_SHARE = 0.05
RANGE_CUT_MIN = 20


def range_cut_notes(grid: MicrolensGrid, settings: PatchSizeSettings, search: tuple[float, float],
                    candidates: np.ndarray, best: np.ndarray, cut: np.ndarray,
                    texture: np.ndarray) -> list[str]:
    """A warning per end of the search (the smallest or the largest candidate) that the
    file's lens-type depth ranges set, not the search's own bounds (``min_px``,
    ``max_fraction D'``), where :data:`RANGE_CUT_SHARE` of the textured lenses (``texture``
    (n,) >= 0.5, whole lenses) matched best: a scene beyond the stated virtual depths,
    whose lenses are then filled from their neighbours. The real files open their outer
    ends (virtual depth 1 to 100), so the search's own bounds hold there; a file with a
    tight range, or one in another virtual-depth convention than ``P = D / v``, is cut.
    ``search``: the searched range (:func:`type_ranges`' lowest and highest bounds), set by
    the file where it lies inside the search's own bounds."""
    c = grid.calib
    textured = (texture >= 0.5) & grid.inside()
    m = int(textured.sum())
    notes = []
    if m == 0:
        return notes
    ends = (("smallest", 0, search[0] > settings.min_px + 1e-9,
             "beyond the largest virtual depth stated"),
            ("largest", len(candidates) - 1,
             search[1] < settings.max_fraction * c.safe_diameter - 1e-9,
             "below the smallest virtual depth stated"))
    for name, index, from_file, where in ends:
        hit = int((textured & cut & (best == index)).sum())
        if from_file and hit >= max(RANGE_CUT_MIN, RANGE_CUT_SHARE * m):
            notes.append(
                f"{100 * hit / m:.0f}% of the textured lenses ({hit} of {m}) matched best at "
                f"the {name} patch size searched, {candidates[index]:.2f} px, which the "
                f"lens types' depth ranges set (P = D / v): the scene seems to reach "
                f"{where}, and those lenses' sizes were filled from their neighbours. "
                f"Widen the lens_type depth_range in {c.source} (the converter reads "
                "virtual depths as v = D / P)")
    return notes


def estimate_patch_size(image: np.ndarray, grid: MicrolensGrid,
                        settings: PatchSizeSettings | None = None, mla: str = "keplerian",
                        threads: int = 1, vignetting: Vignetting | None = None
                        ) -> PatchSizeResult:
    """Patch size of every lens of ``grid`` in ``image`` (see the module docstring);
    the candidate sizes are matched on ``threads`` threads (the same numbers), on blocks
    divided by the micro images' ``vignetting`` profiles where given
    (:func:`match_scores`)."""
    settings = settings or PatchSizeSettings()
    sign = mla_sign(mla)
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
    multi = len({(t.depth_min, t.depth_max) for t in grid.calib.lens_types}) > 1
    scores, pairs, texture = match_scores(gray, grid, candidates, radius,
                                          settings.block_samples, sign,
                                          settings.same_type_ring and multi, threads=threads,
                                          vignetting=vignetting,
                                          texture_scale=settings.texture_scale
                                          if settings.pair_weights else None)
    # lenses cut by the sensor's edge match blocks partly off the image: they lend their
    # scores to no neighbour
    tex = texture_share(texture, settings.texture_scale) * grid.inside() + 1e-3
    scores = aggregate_scores(scores, tex, grid.neighbours, settings.aggregate)

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
            * texture_share(texture, settings.texture_scale))
    # a best match on the edge of the lens type's range or of the whole search is the
    # range cutting off a better match, or (smallest size) the micro images' own structure
    # matching where the scene has nothing to match: not trusted, the lens is filled
    first = np.argmax(allowed, axis=1)
    last = len(candidates) - 1 - np.argmax(allowed[:, ::-1], axis=1)
    cut = (best == first) | (best == last)
    conf = np.where(has & (pairs >= 2) & ~cut, conf, 0.0).astype(np.float32)
    notes = notes + range_cut_notes(grid, settings, (start, stop), candidates, best, cut,
                                    texture_share(texture, settings.texture_scale))
    v_mid = np.sqrt([t.depth_min * min(t.depth_max, 10 * t.depth_min)
                     for t in grid.calib.lens_types])
    fallback = float(np.clip(np.median(grid.diameter / v_mid), t_lo.min(), t_hi.max()))
    patch, more = fill_and_smooth(raw, conf, grid.neighbours, grid.centres / grid.diameter,
                                  settings.min_confidence, settings.smooth_iterations,
                                  fallback)
    # filled lenses may leave their type's range (a neighbour of another type saw the
    # point in focus); the global candidate range still bounds every value
    patch = np.clip(patch, candidates[0], candidates[-1]).astype(np.float32)
    return PatchSizeResult(
        patch=patch, raw=raw.astype(np.float32), confidence=conf,
        confident=conf >= settings.min_confidence, lo=lo, hi=hi, candidates=candidates,
        focus=focus_weights(grid, patch, settings.focus_softness, settings.focus_floor),
        warnings=notes + more, scores=s.astype(np.float32), fallback=fallback,
    )
