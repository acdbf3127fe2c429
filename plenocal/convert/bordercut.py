"""Micro images the main lens cuts at the sensor's borders, and the lenses the views leave out.

A main lens whose aperture clips the bundles of its outermost rays (cat's-eye vignetting)
leaves part of the border lenses' micro images without scene light. The part is the same
in every frame: a region on one side of each micro image, with an edge that moves across
the micro image lens row by lens row (on Boys2, the TSPC test frames: 7.8 px per lens
row over the top four rows, nearly constant along the row). Unlit, it reads black; in a
frame flat-fielded against a white image with the same clipping it reads bright and flat
(Boys2: grey 0.92, where its interior averages 0.36). Views that sample it there show a
flat band along the border, growing with the view's offset towards the cut (Boys2: 6 px
in view row 1, 38 px in row 4); no other lens sees the scene points it hides, so no
blend can fill it. The views leave those lenses out, as they leave out the lenses whose
micro image is not wholly on the sensor (:func:`plenocal.viewgeom.make_layout`: the
views' size stays symmetric about the optical axis, so the crop is the same on the
opposite border and the principal point stays at the views' centre).

Measure (:func:`measure_border_cut`). Per border, the lenses are grouped in bands one
lens row wide (the lattice's spacing along the border's normal), from the border in.
Within the safe disc (``D'``, where the views sample) a position is *flat* where its
grey value changes from one lens of the band to the next along it by less than
:data:`FLAT_SPREAD` of what it does in bands further in (the median absolute difference:
the scene changes from lens to lens; a cut does not, even where a flat-fielded cut dims
slowly along the border), and it is *clipped* or *unlit* where the band's median there is
at least :data:`CLIPPED` or at most :data:`DARK`. A band is cut where its flat clipped
(or flat unlit) positions lie on one side of the micro image: their share of the half
facing one way exceeds that of the half facing the other by :data:`ONE_SIDED` or more.
A flat scene along a border (a black backdrop, a dark floor, an overexposed sky) fills
both halves, and a flat part at a middle grey is the scene's. The border's first band
must be cut; every following band cut the same way (clipped, or unlit, on the same half:
the main lens cuts one side of the border's micro images) is cut too, and the first that
is not ends the border's cut. The lenses of the cut bands are left out.

A position counts at the cut's level only where at least :data:`EVERY_LENS` of the
band's lenses are at it there, not where their median is: the main lens takes the same
part of every micro image of a band, where an overexposed floor or wall saturates most of
a band's lenses, not all. On the real frames the cuts are found as before (Boys2 and
Boys2_f150: the same three bands, the same excess, each band's cut part at the level in
0.97-1.00 of its lenses; Boys2 made 1.15-1.45x brighter: the same four to six bands as
before), and of twelve frames made brighter or darker until up to a third of them clips
(BENCHMARKS.md, "Overexposed frames: lens rows lost to a cut that is not there"), eight
no longer lose lens rows to a cut that is not there (HandTools x1.6-x4 lost 3-6 rows at
the bottom, its one-sided flat part clipped in 0.52-0.67 of the lenses). Not mended: a
scene saturated over most of the outermost bands, its micro images flat on one half only
(Boys2 x1.6: one row on the left, six on the right; Boxer x1.6 two at the top, one
before), and Fujita2 x0.2's black backdrop (one row): rows lost, never wrong pixels; and
a cut beside a scene saturated over both halves of the first band (Boys2 x1.6's top) is
not found, as before.

Decided once per camera, on the central array shot, with the safe diameter (rule
``convert_setup``; ``convert.border_cut``), so every shot's views have one size.
Measured on the eleven frames of ``shared/real`` and the 220 lenslet frames of twelve
simulated captures (seeds 59-64, four geometries): Boys2 and Boys2_f150 cut three bands at
the top (one-sided excess 0.46-0.69, 0.26-0.27 in the third, clipped at grey 0.92; the
fourth band 0.04): their views 1440 x 988 instead of 1064 high, and the flat band of the
lower views (up to 38 px) gone. Nothing else cuts: every other real frame's first bands
read 0 (Fujita2's black backdrop, grey 0.085-0.09, and Boxer's dark floor are flat, but
neither clipped nor unlit, and on both halves where they fill the band), the simulator's
at most 0.011.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np

from plenocal.convert.exact import remap
from plenocal.grid import SENSOR_BORDERS, MicrolensGrid

FLAT_SPREAD = 0.25  # a flat position's lens-to-lens change, of the reference bands'
ONE_SIDED = 0.1  # a cut band's excess of flat share on one half over the other
DARK = 0.05  # grey (0..1) at or under which a flat part is unlit
CLIPPED = 0.8  # grey at or over which a flat part is clipped (flat-fielded)
MAX_BANDS = 10  # bands looked at from each border
MIN_BAND_LENSES = 8  # fewer lenses in a band: the spread says nothing
REFERENCE_BANDS = 6  # bands past MAX_BANDS whose variation is the reference
EVERY_LENS = 0.9  # share of a band's lenses at the cut's level for a position to count


@dataclass(frozen=True)
class BorderCut:
    """Per border (:data:`plenocal.grid.SENSOR_BORDERS`): ``insets_px``, the distance from
    that border (sensor pixels, to a lens centre) under which lenses are left out (0:
    none); ``bands``, the cut bands; ``level``, the grey of the cut part (None where
    none); ``excess``, each band's one-sided flat-share excess as measured (after the
    first band, on the first band's half: negative on the other; for the record)."""

    insets_px: dict[str, float] = field(default_factory=lambda: dict.fromkeys(SENSOR_BORDERS, 0.0))
    bands: dict[str, int] = field(default_factory=lambda: dict.fromkeys(SENSOR_BORDERS, 0))
    level: dict[str, float | None] = field(default_factory=lambda: dict.fromkeys(SENSOR_BORDERS))
    excess: dict[str, list[float]] = field(default_factory=dict)

    @property
    def any(self) -> bool:
        return any(self.bands.values())

    def summary(self) -> str:
        cut = [f"{b} {n} lens row{'s' if n > 1 else ''} (within {self.insets_px[b]:.0f} px "
               f"of the edge, flat at grey {self.level[b]:.2f})"
               for b, n in self.bands.items() if n]
        return ("the main lens cuts the micro images along the sensor's borders: "
                + ", ".join(cut) + "; the views leave those lenses out (and as many on the "
                "opposite side: the views stay centred on the optical axis)") if cut else (
            "no border micro images cut by the main lens")

    def to_dict(self) -> dict:
        return {"insets_px": dict(self.insets_px), "bands": dict(self.bands),
                "level": dict(self.level), "excess": {b: list(v) for b, v in
                                                      self.excess.items()}}

    @classmethod
    def from_dict(cls, d: Mapping) -> BorderCut:
        return cls(insets_px={b: float(d["insets_px"][b]) for b in SENSOR_BORDERS},
                   bands={b: int(d["bands"][b]) for b in SENSOR_BORDERS},
                   level={b: (None if d["level"][b] is None else float(d["level"][b]))
                          for b in SENSOR_BORDERS},
                   excess={b: [float(x) for x in v] for b, v in d.get("excess", {}).items()})


def band_spacing(grid: MicrolensGrid, border: str) -> float:
    """The lens rows' spacing along ``border``'s normal: the least normal component of
    the lattice's three neighbour directions that is over a quarter pitch (rows of a
    hexagonal lattice are ``D sqrt(3) / 2`` or ``D / 2`` apart, as it is turned)."""
    axis = 1 if border in ("top", "bottom") else 0
    a, b = grid.A[:, 0], grid.A[:, 1]
    comp = np.abs(np.array([a[axis], b[axis], a[axis] - b[axis]]))
    return float(comp[comp > grid.diameter / 4].min())


def _micro_images(gray: np.ndarray, centres: np.ndarray, xs: np.ndarray, ys: np.ndarray
                  ) -> np.ndarray:
    """(m, h, w) the square around each centre, bilinear (one remap for all of them)."""
    c = centres.astype(np.float32)
    mx = np.ascontiguousarray(c[:, :1] + xs.ravel()[None, :])
    my = np.ascontiguousarray(c[:, 1:] + ys.ravel()[None, :])
    return remap(gray, mx, my, cv2.INTER_LINEAR).reshape(len(c), *xs.shape)


def _band_lenses(whole: np.ndarray, dist: np.ndarray, along: np.ndarray, lo: float,
                 spacing: float) -> np.ndarray:
    """Indices of the whole lenses whose distance lies in ``[lo, lo + spacing)``, in
    order along the border."""
    band = np.flatnonzero(whole & (dist >= lo) & (dist < lo + spacing))
    return band[np.argsort(along[band], kind="stable")]


def _variation(gray: np.ndarray, centres: np.ndarray, xs: np.ndarray, ys: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """((h, w), (m, h, w)): how much each micro-image position changes from one lens of a
    band to the next along it (the median of the absolute differences: a slow drift along
    the border, as a flat-fielded cut dims towards one end, leaves it near zero; the scene
    does not), and the band's micro images."""
    stack = _micro_images(gray, centres, xs, ys)
    return np.median(np.abs(np.diff(stack, axis=0)), axis=0), stack


def measure_border_cut(gray: np.ndarray, grid: MicrolensGrid, safe_diameter_px: float
                       ) -> BorderCut:
    """Which border bands' micro images the main lens cuts (module docstring).

    ``gray``: the frame, float32 0..1 (:func:`plenocal.convert.shot.frame_gray`)."""
    r = safe_diameter_px / 2
    R = math.ceil(r)
    ys, xs = np.mgrid[-R:R + 1, -R:R + 1].astype(np.float32)
    disc = xs * xs + ys * ys <= r * r
    whole = grid.inside(0.0)
    insets, bands = dict.fromkeys(SENSOR_BORDERS, 0.0), dict.fromkeys(SENSOR_BORDERS, 0)
    levels: dict[str, float | None] = dict.fromkeys(SENSOR_BORDERS)
    excesses: dict[str, list[float]] = {}
    if whole.sum() < MIN_BAND_LENSES:
        return BorderCut()
    for b in SENSOR_BORDERS:
        dist = grid.border_distance(b)
        along = grid.centres[:, 0 if b in ("top", "bottom") else 1]
        spacing = band_spacing(grid, b)
        first = float(dist[whole].min())

        def band_at(k: int, dist=dist, along=along, spacing=spacing, first=first):
            return _band_lenses(whole, dist, along, first + (k - 0.5) * spacing, spacing)

        # the reference: the same variation on bands past those looked at
        refs = [float(np.median(_variation(gray, grid.centres[band], xs, ys)[0][disc]))
                for k in range(MAX_BANDS + 1, MAX_BANDS + 1 + REFERENCE_BANDS)
                if len(band := band_at(k)) >= MIN_BAND_LENSES]
        ref = float(np.median(refs)) if refs else 0.0
        if ref <= 0:
            continue
        outward = (-ys if b == "top" else ys if b == "bottom" else -xs if b == "left" else xs)
        halves = (disc & (outward < -0.5), disc & (outward > 0.5))  # inward, outward
        excess, kind, side, level0, n = [], None, None, None, 0
        for k in range(MAX_BANDS):
            band = band_at(k)
            if len(band) < MIN_BAND_LENSES:
                break
            var, stack = _variation(gray, grid.centres[band], xs, ys)
            flat = var < FLAT_SPREAD * ref
            # each extreme level on its own: a clipped cap beside a black scene (a figure
            # on black) is one-sided as a clipped part, though flat on both halves
            best = None
            for name, at_level in (("clipped", stack >= CLIPPED), ("unlit", stack <= DARK)):
                if kind is not None and name != kind:
                    continue  # the next bands continue the first band's cut
                part = flat & (at_level.mean(axis=0) >= EVERY_LENS)
                shares = [float(part[h].mean()) for h in halves]
                # the next bands continue the first band's cut on its side
                cut_half = int(np.argmax(shares)) if side is None else side
                ex = shares[cut_half] - shares[1 - cut_half]
                if best is None or ex > best[1]:
                    best = (name, ex, cut_half, part & halves[cut_half])
            name, ex, cut_half, part = best
            excess.append(round(ex, 4))
            if ex < ONE_SIDED:
                break
            kind, side = name, cut_half
            if level0 is None:
                level0 = float(np.median(stack, axis=0)[part].mean())
            n = k + 1
        excesses[b] = excess
        if n:
            bands[b] = n
            levels[b] = round(level0, 4)
            # half a band past the last cut band's centre: its lenses out, the next in
            insets[b] = round(first + (n - 0.5) * spacing, 4)
    return BorderCut(insets_px=insets, bands=bands, level=levels, excess=excesses)
