"""The micro-image centres found by the views' agreement, where the grid check cannot see them.

The grid check (:mod:`plenocal.convert.gridcheck`) measures the lattice by the borders
and rims of the micro images. A frame whose micro images tile without rims and carry
strong texture of their own defeats it: R42_klein_crop (Raytrix R42, far content at
virtual depth 5.5) measures 14 % of its lit lenses, the check cannot confirm the file's
grid (``verified`` false) and ``convert.grid: auto`` keeps it. Its corner view 0_0 then
showed a row of crescents under the blue rod that the opposite corner 4_4 did not.

Principle. View (r, c) samples every lens at ``m_i + q_rc``, ``m_i`` the micro-image
centre. Where the centres are off by ``delta``, the views on one side sample a lens
``|q_rc + delta|`` from its true centre, nearer its rim, and those on the other side
farther in: the four corner views, which reach farthest, are unbalanced, and the lenses
blended into a pixel of the worse corner disagree (each sees the point from another place
near its rim, the neighbours' light and the blur of the rim in it). The mean disagreement
of the four corner views, over the lattice moved by ``delta`` (:func:`corner_disagreement`,
the lenses' weighted mean absolute deviation from their blend, grey levels), is least
where ``delta`` puts the lattice on the micro images.

Measured (:func:`measure_centring` forced on every frame of ``shared/real/frames``, on
the grid each converts with; BENCHMARKS.md, "R42's grid moved onto its micro images by
the corner views' agreement"): the ten frames whose grids the check confirms find their
least disagreement within 0.25-2 px of that grid and 0.1-0.9 % below it (the TSPC frames'
70-px micro images the flattest), four of the simulator's shots 0.0-0.1 %, subjects on
black at most 1.2 %; R42_klein_crop finds (+3.25, +2.25) px, 25.7 % below the file's grid
(the same on three crops of it, after a YUV 4:2:0 round trip, darker and noisier), and the
crescents of its view 0_0 fade (issue 33). Synthetic frames with soft micro-image rims and
a grid moved 1.5-2.5 px are found within 0.25 px (``tests/test_centring.py``).

Use (:func:`plenocal.convert.setup.centring_for`): where ``convert.grid`` is ``auto`` and the check
could not confirm the file's grid (not foreign, not refined), the file's lattice is moved
by the ``delta`` a pattern search finds (steps of 2, 1, 0.5 and 0.25 px from the file's
grid, at most :data:`MAX_SHIFT_LENSES` of a lens) when it is at least
:data:`MIN_SHIFT_PX` long and lowers the disagreement by at least :data:`MIN_GAIN`. The
frame is then measured again on the moved grid (patch sizes, vignetting profiles, safe
diameter: every measure reads the micro images around their centres). Frames whose grid
the check confirms are not touched: their views, and the simulator's (every calibration
figure), stay the same bytes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from plenocal.convert.render import RenderPlan, slot_samples, view_weights
from plenocal.grid import MicrolensGrid
from plenocal.viewgeom import remembered_slots, slots_remembered

if TYPE_CHECKING:
    from plenocal.convert.shot import ShotConversion

#: a shift shorter than this is not applied: a centre error ``e`` moves a lens's tile by
#: ``e T / P`` output pixels, and half a pixel is the grid check's own bar
#: (:mod:`plenocal.convert.gridcheck`, "Why 1 px")
MIN_SHIFT_PX = 0.5
#: the least relative fall of the corner views' disagreement for a shift to be applied:
#: between what right grids show when the search is forced on them (at most 1.2 %) and what
#: R42's file grid shows (25.7 %), far from both
MIN_GAIN = 0.05
#: the search reaches at most this share of the lens pitch from the file's grid (a grid
#: further off is a mosaic the check would see, or another camera's file)
MAX_SHIFT_LENSES = 0.25
#: the search's steps (px), each searched until no neighbour of the best is better
STEPS_PX = (2.0, 1.0, 0.5, 0.25)
#: output rows a band; at most :data:`MAX_BANDS` bands spread over the view are measured,
#: and no more than hold :data:`MAX_PIXELS` output pixels (at least :data:`MIN_BANDS`): the
#: shift is one for the whole frame, and three crops of R42_klein_crop of 232-345 lit lenses
#: each found the whole crop's (BENCHMARKS.md)
BAND_ROWS = 32
MAX_BANDS = 8
MIN_BANDS = 3
MAX_PIXELS = 8 * BAND_ROWS * 1024


@dataclass(frozen=True)
class CentringFit:
    """The search's result: ``offset_px`` (x, y) moves the file's lattice onto the micro
    images (image axes); the corner views' disagreement there and at the file's grid."""

    offset_px: tuple[float, float]
    disagreement_file: float
    disagreement_fit: float
    evaluations: int
    applied: bool

    @property
    def gain(self) -> float:
        """The relative fall of the disagreement at the fit."""
        if self.disagreement_file <= 0:
            return 0.0
        return 1.0 - self.disagreement_fit / self.disagreement_file

    def to_dict(self) -> dict:
        return {"offset_px": [float(v) for v in self.offset_px],
                "disagreement_file": round(self.disagreement_file, 6),
                "disagreement_fit": round(self.disagreement_fit, 6),
                "evaluations": int(self.evaluations), "applied": bool(self.applied),
                "rule": (f"moved where the shift is >= {MIN_SHIFT_PX} px and the corner "
                         f"views' disagreement falls by >= {100 * MIN_GAIN:g} % "
                         "(plenocal.convert.centring)")}


def _bands(height: int, width: int, margin: int) -> list[slice]:
    """Bands of :data:`BAND_ROWS` rows spread evenly over the view's rows ``margin ..
    height - margin`` (all of them on a small view): at most :data:`MAX_BANDS`, and no
    more than :data:`MAX_PIXELS` output pixels in all unless that is under
    :data:`MIN_BANDS` bands."""
    lo, hi = margin, max(margin + 1, height - margin)
    starts = list(range(lo, hi, BAND_ROWS))
    most = max(MIN_BANDS, min(MAX_BANDS, MAX_PIXELS // (BAND_ROWS * max(width, 1))))
    if len(starts) > most:
        pick = np.linspace(0, len(starts) - 1, most).round().astype(int)
        starts = [starts[i] for i in pick]
    return [slice(s, min(s + BAND_ROWS, hi)) for s in starts]


def _plan_disagreement(plan: RenderPlan, grey: np.ndarray, r: int, c: int
                       ) -> tuple[float, int]:
    """(sum over the plan's pixels of the weighted mean absolute deviation of the lenses'
    grey samples from their blend; the number of pixels) of view (r, c). The samples are
    not devignetted: the profiles were measured around the centres under test, and
    divided out they bent the measure (synthetic micro images with soft rims, the grid
    moved 1-2.5 px: found 1-2 px off with the profiles, within 0.25 px without). They are
    read as the views read them (:func:`plenocal.convert.render.slot_samples`) from the
    integer ``grey`` (integer interpolation: the same values on every machine)."""
    o = plan.layout.offset_image(r, c)
    w = view_weights(plan, r, c)
    blended = np.zeros(w.shape[1:], np.float32)
    samples = []
    for k in range(w.shape[0]):
        s = slot_samples(plan, grey, k, o).astype(np.float32)
        samples.append(s)
        blended += w[k] * s
    dev = np.zeros_like(blended)
    for k, s in enumerate(samples):
        s -= blended
        np.abs(s, out=s)
        s *= w[k]
        dev += s
    return float(dev.sum(dtype=np.float64)), int(dev.size)


def corner_disagreement(shot: ShotConversion, offset_px: tuple[float, float], grey: np.ndarray,
                        bands: list[slice]) -> float:
    """The four corner views' mean disagreement (grey levels of ``grey``) over output
    ``bands`` with the shot's micro-image centres moved by ``offset_px``. ``shot``: a
    :class:`plenocal.convert.shot.ShotConversion` (its lenses, patch sizes and blends)."""
    layout = dataclasses.replace(
        shot.layout, lens_centres=shot.layout.lens_centres + np.asarray(offset_px, float))
    n = shot.n_views - 1
    corners = ((0, 0), (0, n), (n, 0), (n, n))
    total, count = 0.0, 0
    for rows in bands:
        plans = {b: shot.blend_plan(rows, b, layout)
                 for b in sorted({shot.blend_of(r, c) for r, c in corners})}
        for r, c in corners:
            s, m = _plan_disagreement(plans[shot.blend_of(r, c)], grey, r, c)
            total += s
            count += m
    return total / max(count, 1)


def grey_source(shot: ShotConversion) -> np.ndarray:
    """The shot's render source in grey, integers (OpenCV's fixed-point conversion)."""
    src, _ = shot.render_source
    if src.ndim == 2 or src.shape[2] == 1:
        return np.ascontiguousarray(src.reshape(src.shape[:2]))
    return cv2.cvtColor(src, cv2.COLOR_RGB2GRAY)


def measure_centring(shot: ShotConversion) -> CentringFit:
    """The lattice shift (px) that the four corner views of ``shot`` agree on best
    (:func:`corner_disagreement`), by a pattern search from the file's grid over
    :data:`STEPS_PX`, at most :data:`MAX_SHIFT_LENSES` of the pitch away; ``applied`` per
    :data:`MIN_SHIFT_PX` and :data:`MIN_GAIN`. Deterministic: the shifts are multiples of
    a quarter pixel, the samples integer interpolations, and a neighbour replaces the best
    only where it is lower by more than one part in 10^9."""
    if shot.n_views < 3:
        return CentringFit((0.0, 0.0), 0.0, 0.0, 0, False)
    with contextlib.nullcontext() if slots_remembered() else remembered_slots():
        return _search(shot)


def _search(shot: ShotConversion) -> CentringFit:
    """:func:`measure_centring`'s search (the nearest-lens tables, which the moved
    lattices share, made once: :func:`plenocal.viewgeom.remembered_slots`)."""
    grey = grey_source(shot)
    bands = _bands(shot.layout.height, shot.layout.width, int(shot.layout.tile))
    reach = MAX_SHIFT_LENSES * float(shot.grid.diameter)
    memo: dict[tuple[float, float], float] = {}

    def cost(p: tuple[float, float]) -> float:
        if p not in memo:
            memo[p] = corner_disagreement(shot, p, grey, bands)
        return memo[p]

    best = (0.0, 0.0)
    for step in STEPS_PX:
        moved = True
        while moved:
            moved = False
            around = [(best[0] + dx * step, best[1] + dy * step)
                      for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dx or dy]
            for p in around:
                if math.hypot(*p) > reach:
                    continue
                if cost(p) < cost(best) * (1.0 - 1e-9):
                    best, moved = p, True
    at_file, at_fit = cost((0.0, 0.0)), cost(best)
    fit = CentringFit(best, at_file, at_fit, len(memo), False)
    applied = math.hypot(*best) >= MIN_SHIFT_PX and fit.gain >= MIN_GAIN
    return dataclasses.replace(fit, applied=applied)


def shifted_grid(grid: MicrolensGrid, offset_px: tuple[float, float]) -> MicrolensGrid:
    """``grid``'s lattice moved by ``offset_px`` (its vectors and lens types kept)."""
    return MicrolensGrid(grid.calib, grid.width, grid.height,
                         lattice=(grid.origin + np.asarray(offset_px, float), grid.A.copy()))
