"""Registration B: the N x N subaperture set of one plenoptic camera (Section II-C).

Inputs: the datasheet (``camera.yaml``), the converter's ``disparity.json`` of every
shot, and the multiview focal length ``F_m`` (pixels) from registration A. Output:
``rig.json`` with every view's intrinsics ``K`` and its pose relative to the central
view (``cam_to_central``, metres, OpenCV axes), the paper's symbols, the inverse
check of Eqs. 2-3 and both view models:

``paper``
    Section II-C verbatim: principal point centred, views on a plane spaced
    ``B = F tan(beta)``, turned by ``n alpha`` per axis towards the convergence
    point at ``X_c = B / tan(alpha)`` (Eq. 4, :func:`plenocal.optics.view_extrinsic`;
    symbols: :mod:`plenocal.calib.reg_b.paper_model`).

``exact``
    What the optics of this converter give (:mod:`plenocal.calib.reg_b.exact_model`):
    no rotation, centres spaced ``B_e = L q / s``, principal point shifted per step.

Units: poses in metres; the ``symbols``, ``paper`` and ``exact`` blocks in
millimetres and radians. Pixel centres at integer coordinates.

The MLA kind (Keplerian or Galilean; :mod:`plenocal.calib.reg_b.paper_model`)
comes from the converter's ``disparity.json`` (key ``mla``, decided once per
dataset; a file without it predates Galilean support and is Keplerian).
The comparison of a ``rig.json`` with the simulator's ground truth is
:mod:`plenocal.verify.rig_truth`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict
from statistics import median

import numpy as np

from plenocal import optics as o
from plenocal.artifacts.disparity import Conversion
from plenocal.calib.reg_b.datasheet import Datasheet
from plenocal.calib.reg_b.exact_model import exact_model
from plenocal.calib.reg_b.paper_model import inverse_check, paper_symbols
from plenocal.camera import intrinsics
from plenocal.config import stage_defaults
from plenocal.names import parse_view, view_names
from plenocal.viewgeom import view_position

RIG_MODELS = ("exact", "paper")
_RIG = stage_defaults("rig")  # build_rig's defaults: config.schema.yaml's rig block


def combine_conversions(convs: Sequence[Conversion], names: Sequence[str] | None = None
                        ) -> Conversion:
    """One conversion for the dataset (same camera for every shot): the median of the
    disparity range across shots; the geometry (q, T, D, size) must agree."""
    if not convs:
        raise ValueError("registration B needs the disparity.json of at least one shot")
    first = convs[0]
    names = list(names) if names is not None else [str(i) for i in range(len(convs))]
    for name, c in zip(names, convs, strict=True):
        if (c.width, c.height, c.tile) != (first.width, first.height, first.tile) or \
                abs(c.q - first.q) > 1e-6 * max(1.0, abs(first.q)):
            raise ValueError(f"shot {name}: view size / tile / q differ from shot {names[0]} "
                             "- every shot must be converted with the same settings")
        if c.mla != first.mla:
            raise ValueError(f"shot {name}: disparity.json says mla {c.mla}, shot {names[0]}'s "
                             f"{first.mla}: one camera has one MLA kind; set convert.mla (or "
                             "the dataset's mla) and convert again")
    return Conversion(
        d_min=float(median(c.d_min for c in convs)),
        d_max=float(median(c.d_max for c in convs)),
        q=first.q, tile=first.tile,
        pitch_px=float(median(c.pitch_px for c in convs)),
        safe_diameter_px=float(median(c.safe_diameter_px for c in convs)),
        width=first.width, height=first.height, n_views=first.n_views, mla=first.mla,
    )



def view_cameras(model: str, n_views: int, width: int, height: int, F_m: float,
                 B_mm: float, alpha: float = 0.0, pp_shift_px: float = 0.0
                 ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """K and cam_to_central (metres) of every view ``r_c`` of an N x N set.

    ``paper``: K centred, pose Eq. 4 ``[R(h alpha, v alpha) | (h B, v B, 0)]``.
    ``exact``: no rotation, centre ``(h B, v B, 0)``, principal point
    ``((W-1)/2 + h shift, (H-1)/2 + v shift)``."""
    if model not in RIG_MODELS:
        raise ValueError(f"rig model must be one of {', '.join(RIG_MODELS)} (got {model!r})")
    cx0, cy0 = (width - 1) / 2.0, (height - 1) / 2.0
    B = B_mm / 1000.0
    out = {}
    for name in view_names(n_views):
        h, v = view_position(*parse_view(name), n_views)
        if model == "paper":
            K = intrinsics(F_m, cx0, cy0)
            M = o.view_extrinsic(h, v, B, alpha)
        else:
            K = intrinsics(F_m, cx0 + h * pp_shift_px, cy0 + v * pp_shift_px)
            M = np.eye(4)
            M[:3, 3] = (h * B, v * B, 0.0)
        out[name] = (K, M)
    return out


def depth_range_m(near_mm: float, far_mm: float, margin: float = 0.1) -> tuple[float, float]:
    """The depth range written for the MPEG tools (metres): the scene range widened by
    ``margin`` on each side (hand-held shots come closer or go farther than the array)."""
    return near_mm * (1.0 - margin) / 1000.0, far_mm * (1.0 + margin) / 1000.0


def build_rig(ds: Datasheet, convs: Sequence[Conversion], F_m: float, n_views: int,
              model: str = _RIG["model"], tolerance: float = _RIG["check_tolerance"],
              shot_names: Sequence[str] | None = None) -> dict:
    """The content of ``rig.json`` (both models computed; ``model`` fills ``views``)."""
    if model not in RIG_MODELS:
        raise ValueError(f"config rig.model must be one of {', '.join(RIG_MODELS)} "
                         f"(got {model!r})")
    if not F_m > 0:
        raise ValueError(f"registration A's focal length must be positive (got {F_m})")
    conv = combine_conversions(convs, shot_names)
    if conv.n_views is not None and conv.n_views != n_views:
        raise ValueError(f"disparity.json says {conv.n_views} views per side, the config "
                         f"{n_views}: convert again with the current config")
    sym = paper_symbols(ds, conv, F_m, n_views)
    ex = exact_model(sym)
    check_paper = inverse_check(sym, ds.near, ds.far, sym["B"], sym["alpha"], tolerance)
    check_exact = inverse_check(sym, ds.near, ds.far, ex["B"], ex["alpha_equivalent"],
                                tolerance)
    W, H = conv.width, conv.height
    if model == "paper":
        cams = view_cameras("paper", n_views, W, H, F_m, sym["B"], alpha=sym["alpha"])
    else:
        cams = view_cameras("exact", n_views, W, H, F_m, ex["B"], pp_shift_px=ex["pp_shift_px"])
    near = ds.near if ds.near is not None else sym["X_n"]
    far = ds.far if ds.far is not None else sym["X_f"]
    if not (near and far and 0 < near < far):
        raise ValueError(f"no usable depth range: near {near} mm, far {far} mm (give "
                         "scene.near_mm/far_mm in camera.yaml)")
    return {
        "model": model,
        "mla": conv.mla,
        "units": "m",
        "width": W,
        "height": H,
        "n_views": n_views,
        "focal_px": F_m,
        "depth_range_m": list(depth_range_m(near, far)),
        "views": {k: {"K": K, "cam_to_central": M} for k, (K, M) in cams.items()},
        "symbols": sym,
        "paper": {"B": sym["B"], "alpha": sym["alpha"], "X_c": sym["X_c"],
                  "pp_shift_px": 0.0, "check": check_paper},
        "exact": dict(ex, check=check_exact),
        "check": check_exact if model == "exact" else check_paper,
        "shots": list(shot_names) if shot_names is not None else None,
        "datasheet": asdict(ds),
        "disparity": asdict(conv),
    }


def model_views(rig: Mapping, model: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(K, cam_to_central) of either view model from a ``rig.json`` document, whichever
    model its ``views`` hold (both models' numbers are stored)."""
    n, W, H, F_m = int(rig["n_views"]), int(rig["width"]), int(rig["height"]), rig["focal_px"]
    if model == "paper":
        return view_cameras("paper", n, W, H, F_m, rig["paper"]["B"], alpha=rig["paper"]["alpha"])
    return view_cameras(model, n, W, H, F_m, rig["exact"]["B"],
                        pp_shift_px=rig["exact"]["pp_shift_px"])



def rig_at_focal(doc: Mapping, F_m: float) -> dict:
    """Registration B's rig (a ``rig.json`` document) built again for the focal length
    ``F_m`` (pixels) from the datasheet, the conversion and the settings it was built
    with: the views' baselines and principal points follow the focal length (Eqs. 1-4,
    :func:`plenocal.calib.reg_b.exact_model.exact_model`). Used by the joint refinement
    (:mod:`plenocal.calib.refine`) when it refines the focal length."""
    ds = Datasheet(**{**doc["datasheet"], "f_numbers": tuple(doc["datasheet"]["f_numbers"])})
    conv = Conversion(**doc["disparity"])
    tol = doc["check"].get("tolerance", _RIG["check_tolerance"])
    return build_rig(ds, [conv], float(F_m), int(doc["n_views"]), model=str(doc["model"]),
                     tolerance=float(tol), shot_names=None)
