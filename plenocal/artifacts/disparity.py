"""``disparity.json``: the converter's record of one shot, read by registration B.

One typed definition for the file: :func:`disparity_record` writes it (rule
``convert`` and ``plenocal convert``), :func:`read_disparity` reads the part that
registration B uses into a :class:`Conversion`, :func:`read_disparity_warnings` the
conversion's warnings for the report. The file carries its format name and
version; a file of another version is refused with the remedy (convert again), never
guessed at.

The disparity is the paper's (Eq. 1): ``D = u_h - u_(h+1)``, a point's x in view (r, c)
minus its x in view (r, c+1), in output pixels. Keplerian MLA: ``D = -q T / P`` (the scene
lies beyond the plane conjugate to the MLA, where the views converge); Galilean:
``D = +q T / P``. ``D_max`` belongs to the nearest object.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.stage_warnings import WARNINGS_KEY, warning_list, warnings_of
from plenocal.artifacts.versioned import decode
from plenocal.io.raytrix import RayCalib
from plenocal.viewgeom import MLA_KINDS, ViewLayout

FORMAT = "plenocal.disparity"
VERSION = 1


@dataclass(frozen=True)
class Conversion:
    """What registration B takes from one shot's ``disparity.json``.

    ``d_min``/``d_max`` in the paper's sign (Eq. 1): ``d_max`` belongs to the nearest
    object."""

    d_min: float
    d_max: float
    q: float  # view spacing on the sensor, pixels
    tile: float  # T, output pixels per micro-image pitch
    pitch_px: float  # D, micro-image pitch, sensor pixels
    safe_diameter_px: float  # D'
    width: int  # view size
    height: int
    n_views: int | None = None
    mla: str = "keplerian"  # MLA kind: keplerian (micro images inverted) or galilean


def disparity_record(layout: ViewLayout, calib: RayCalib, patch: np.ndarray,
                     confident: np.ndarray, percentiles: tuple[float, float] = (2.0, 98.0),
                     warnings: Iterable[str] = (), safe_diameter: float | None = None) -> dict:
    """The content of ``disparity.json``: the disparity range between horizontally
    adjacent views (Eq. 1), the geometry it refers to, the patch-size statistics
    (``patch``/``confident``: per used lens) and the conversion's ``warnings``
    (:mod:`plenocal.artifacts.stage_warnings`). The range is taken between the given
    percentiles of the confident lenses' patch sizes (all lenses' where none is
    confident; ``patch_size_px.range``): a size filled in where matching had nothing to
    match is no measured depth (a doll on black once gave D_min = -178 px from its filled
    background).
    ``safe_diameter``: the ``D'`` the views were cut with (default: calib.xml's
    ``D - 2 lens_border``)."""
    q, T = layout.q, layout.tile
    d_safe = float(calib.safe_diameter if safe_diameter is None else safe_diameter)
    confident = np.asarray(confident, dtype=bool)
    measured = patch[confident] if confident.any() else patch
    p_lo, p_hi = (float(x) for x in np.percentile(measured, percentiles))
    sign = layout.sign
    # |u_(h+1) - u_h| of the farthest and nearest points: Keplerian far = small P
    shift_far, shift_near = (q * T / p_lo, q * T / p_hi) if sign < 0 else (q * T / p_hi,
                                                                             q * T / p_lo)
    pct = {f"p{int(p):02d}": float(np.percentile(patch, p)) for p in (2, 10, 25, 50, 75, 90, 98)}
    return {
        "format": FORMAT,
        "version": VERSION,
        "convention": "paper",
        "convention_note": (
            "D = u_h - u_(h+1): a point's x in view (r, c) minus its x in view (r, c+1), "
            "output pixels (the paper's Eq. 1). Keplerian MLA: D = -q T / P, negative, "
            "because the scene lies beyond the plane conjugate to the MLA (Z0), where the "
            "views converge; Galilean MLA: D = +q T / P. D_max belongs to the nearest "
            "object (largest P for Keplerian, smallest for Galilean). shift_* are the "
            "magnitudes |D| = q T / P."),
        "mla": layout.mla,
        "D_min": sign * shift_far,
        "D_max": sign * shift_near,
        "shift_far_px": shift_far,
        "shift_near_px": shift_near,
        "percentiles": list(percentiles),
        "q_px": q,
        "q_formula": ("q = D' sin(45 deg) / N (the paper) with D' = safe_diameter_px "
                      "(convert.safe_diameter), unless convert.view_spacing_px is set"),
        "q_paper_px": d_safe * math.sin(math.radians(45.0)) / layout.n_views,
        "tile": T,
        "D_px": calib.diameter,
        "safe_diameter_px": d_safe,
        "safe_diameter_file_px": float(calib.safe_diameter),
        "n_views": layout.n_views,
        "width": layout.width,
        "height": layout.height,
        "used_lenses": int(len(patch)),
        "patch_size_px": {
            "min": float(np.min(patch)), "max": float(np.max(patch)),
            "median": float(np.median(patch)), "mean": float(np.mean(patch)),
            "percentiles": pct,
            "confident_share": float(np.mean(confident)) if len(confident) else 0.0,
            "filled_share": float(1.0 - np.mean(confident)) if len(confident) else 1.0,
            "range": [p_lo, p_hi],
            "range_from": "confident lenses" if confident.any() else "all lenses (none "
                          "confident)",
        },
        WARNINGS_KEY: warning_list(warnings),
    }


REMEDY = "convert the shot (rule convert, or plenocal convert)"


def read_disparity(path: str | Path) -> Conversion:
    """Read one shot's ``disparity.json`` (this version only) into a :class:`Conversion`."""
    return decode(path, FORMAT, VERSION, "disparity.json", REMEDY,
                  lambda doc: _conversion(doc, path))


def _conversion(doc: dict, path: str | Path) -> Conversion:
    mla = str(doc["mla"])
    if mla not in MLA_KINDS:
        raise ValueError(f"{path}: mla = {mla!r} is not an MLA kind (one of "
                         f"{', '.join(MLA_KINDS)}); convert the shot again")
    a, b = float(doc["D_min"]), float(doc["D_max"])
    return Conversion(
        d_min=min(a, b), d_max=max(a, b), q=float(doc["q_px"]), tile=float(doc["tile"]),
        pitch_px=float(doc["D_px"]), safe_diameter_px=float(doc["safe_diameter_px"]),
        width=int(doc["width"]), height=int(doc["height"]), n_views=int(doc["n_views"]),
        mla=mla)


def read_disparity_warnings(path: str | Path) -> tuple[str, ...]:
    """What the conversion of the shot warned about (the ``warnings`` of
    ``disparity.json``, this version only): for the report's first screen."""
    return decode(path, FORMAT, VERSION, "disparity.json", REMEDY,
                  lambda doc: warnings_of(doc, path, REMEDY))


def read_confident_share(path: str | Path) -> float:
    """The share of the shot's lenses whose patch size was measured, not filled
    (``patch_size_px.confident_share`` of ``disparity.json``, this version only)."""
    return decode(path, FORMAT, VERSION, "disparity.json", REMEDY,
                  lambda doc: float(doc["patch_size_px"]["confident_share"]))
