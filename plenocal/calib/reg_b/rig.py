"""Registration B: the N x N subaperture set of one plenoptic camera (Section II-C).

Inputs: the datasheet (``camera.yaml``), the converter's ``disparity.json`` of every
shot, and the multiview focal length ``F_m`` (pixels) from registration A. Output:
``rig.json`` with every view's intrinsics ``K`` and its pose relative to the central
view (``cam_to_central``, metres, OpenCV axes), the paper's symbols, the inverse
check of Eqs. 2-3 and both view models:

``paper``
    Section II-C verbatim: principal point centred, views on a plane spaced
    ``B = F tan(beta)``, turned by ``n alpha`` per axis towards the convergence
    point at ``X_c = B / tan(alpha)`` (Eq. 4, :func:`plenocal.optics.view_extrinsic`).

``exact``
    What the optics of this converter give (:func:`exact_model`): no rotation,
    centres spaced ``B_e = L q / s``, principal point shifted per step.

Units: lengths in millimetres and angles in radians inside ``symbols``, ``paper``
and ``exact``; poses in metres. Pixel centres at integer coordinates.

Disparity sign. The paper's Eq. 1 (``X = B F / (C + d P)``) uses ``d = u_h - u_{h+1}``,
the shift of a point from a view to its right-hand neighbour, counted positive to the
left: ``d = F_m (B / X - tan(alpha))``, larger for nearer objects (negative beyond
the convergence distance). The converter may report the opposite sign; see
:func:`plenocal.artifacts.disparity.read_disparity`.

MLA kinds. The paper's Fig. 2 is Keplerian: the main lens images the scene ``t > 0`` in
front of the MLA. In a Galilean camera the MLA stands in front of that image, which
the microlenses see as a virtual object ``|t|`` behind them: ``s < f`` and the signed
``t = s f / (s - f)`` is negative. Everything else of Section II-C and of the exact
model holds with the signed ``t`` (the chief rays, hence the views, do not depend on
the kind): the MLA lies at ``L = F + e + t``, the views converge at the plane
conjugate to the MLA, ``Z0 = F L / (L - F)``, and the paper's ``C = (e + t) tan(beta)``
is the same quantity with the paper's ``F``. What differs:

* where the views converge. Keplerian: ``L > F + e``, so ``Z0 < X_o``: the scene lies
  beyond the convergence plane and every disparity is negative (the converter's
  ``D = -q T / P``). Galilean: ``L < F + e``, so ``Z0 > X_o``: the views converge behind
  the scene (a few metres for the tiny set-up) and the disparities are positive
  (``D = +q T / P``); when ``e < |t|`` (focus far away) even ``L < F``: ``Z0`` and
  ``alpha`` are negative, the views diverge and ``X_c`` is negative.
* ``s`` from the datasheet's ``k`` when ``mla.sensor_distance_mm`` is absent:
  ``k f / (k - 1)`` (the paper; sharp plane ``t = k f`` in front of the MLA) or
  ``k f / (k + 1)`` (Galilean; sharp virtual plane ``k f`` behind it), the convention
  of the simulator (``config.schema.yaml``, ``simulate.mla.k``) and of
  :class:`plenocal.optics.PlenopticOptics`.
* the accuracy of the paper's ``alpha``: ``e + t`` is a small difference for a
  Galilean camera, so the paper's ``F = F_m P = L + s`` (instead of the true focal
  length) in ``e`` moves it by ~20 % instead of ~2 %.

The kind comes from the converter's ``disparity.json`` (key ``mla``, decided once per
dataset; a file without it predates Galilean support and is Keplerian).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from statistics import median

import numpy as np

from plenocal import optics as o
from plenocal.artifacts.disparity import Conversion
from plenocal.artifacts.rig import RigB
from plenocal.calib.reg_b.datasheet import load_datasheet
from plenocal.camera import PinholeCamera, intrinsics, invert_pose, rotation_angle_deg
from plenocal.names import central_view, parse_view, view_names
from plenocal.viewgeom import MLA_KINDS, view_position

RIG_MODELS = ("exact", "paper")


# ---------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Datasheet:
    """What ``camera.yaml`` gives (millimetres)."""

    pixel_size: float  # p
    sensor_width: int
    sensor_height: int
    focus_distance: float  # X_o
    focal_length_nominal: float  # main lens, nominal (information only: F comes from F_m P)
    mla_pitch: float  # D, physical
    f_numbers: tuple[float, ...]
    k: float
    sensor_distance: float | None  # s, if the datasheet gives it
    array_step: float | None
    near: float | None  # measured X_n
    far: float | None  # measured X_f


def _need(doc: Mapping, path: str, source: str | Path):
    cur: object = doc
    for part in path.split("."):
        if not isinstance(cur, Mapping) or part not in cur:
            raise ValueError(f"{source}: missing key {path!r} (the datasheet must give it; "
                             "see plenocal/calib/reg_b/rig.py read_datasheet for the expected "
                             "keys)")
        cur = cur[part]
    return cur


def _opt(doc: Mapping, path: str):
    cur: object = doc
    for part in path.split("."):
        if not isinstance(cur, Mapping) or part not in cur or cur[part] is None:
            return None
        cur = cur[part]
    return cur


def read_datasheet(path: str | Path) -> Datasheet:
    """Read ``camera.yaml``: pixel_size_mm, sensor_width_px, sensor_height_px,
    main_lens.{focus_distance_mm, focal_length_mm}, mla.{pitch_mm, f_numbers, k,
    sensor_distance_mm (optional)}, array.step_mm, scene.{near_mm, far_mm}. Without
    sensor_distance_mm, ``s`` follows from ``k`` by the MLA kind of the converter's
    disparity.json (:func:`sensor_distance`).

    Validated against :data:`plenocal.calib.reg_b.datasheet.SCHEMA` first: a bad value raises
    :class:`plenocal.calib.reg_b.datasheet.DatasheetError` naming the file and the key."""
    path = Path(path)
    doc = load_datasheet(path)
    fn = _need(doc, "mla.f_numbers", path)
    fns = tuple(float(x) for x in (fn if isinstance(fn, list | tuple) else [fn]))
    opt_f = lambda key: None if _opt(doc, key) is None else float(_opt(doc, key))  # noqa: E731
    return Datasheet(
        pixel_size=float(_need(doc, "pixel_size_mm", path)),
        sensor_width=int(_need(doc, "sensor_width_px", path)),
        sensor_height=int(_need(doc, "sensor_height_px", path)),
        focus_distance=float(_need(doc, "main_lens.focus_distance_mm", path)),
        focal_length_nominal=float(_opt(doc, "main_lens.focal_length_mm") or float("nan")),
        mla_pitch=float(_need(doc, "mla.pitch_mm", path)),
        f_numbers=fns,
        k=float(_need(doc, "mla.k", path)),
        sensor_distance=opt_f("mla.sensor_distance_mm"),
        array_step=opt_f("array.step_mm"),
        near=opt_f("scene.near_mm"),
        far=opt_f("scene.far_mm"),
    )


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


# ---------------------------------------------------------------------------
# The paper's model (Section II-C, Eqs. 1-4)
# ---------------------------------------------------------------------------


def sensor_distance(k: float, f: float, mla: str) -> float:
    """``s`` from the datasheet's ``k``: ``k f / (k - 1)`` for a Keplerian MLA (the paper),
    ``k f / (k + 1)`` for a Galilean one (sharp virtual plane ``k f`` behind the MLA)."""
    if mla == "galilean":
        if k <= 0:
            raise ValueError(f"camera.yaml: mla.k = {k}: must be > 0")
        return k * f / (k + 1.0)
    return o.mla_sensor_distance(k, f)


def sharp_distance(s: float, f: float, mla: str) -> float:
    """Signed ``t = s f / (s - f)``: > 0 (Keplerian, ``s > f``: the sharp plane is in
    front of the MLA), < 0 (Galilean, ``s < f``: a virtual plane behind it). A sensor
    distance on the wrong side of ``f`` for the MLA kind raises."""
    if mla not in MLA_KINDS:
        raise ValueError(f"MLA kind must be one of {', '.join(MLA_KINDS)} (got {mla!r})")
    keplerian = mla == "keplerian"
    if s == f or (s > f) != keplerian:
        raise ValueError(
            f"camera.yaml: the MLA-sensor distance s = {s:.6g} mm is "
            f"{'not above' if keplerian else 'not below'} the microlens focal length "
            f"f = F_n D = {f:.6g} mm, but disparity.json says the MLA is {mla} (which needs "
            f"s {'>' if keplerian else '<'} f): check mla.sensor_distance_mm / mla.k / "
            "mla.f_numbers, or the MLA kind (convert.mla, the dataset's mla)")
    return s * f / (s - f)


def paper_symbols(ds: Datasheet, conv: Conversion, F_m: float, n_views: int) -> dict:
    """Every symbol of Section II-C (mm, rad), with the converter's q.

    ``P = p w/W``; for this converter ``w/W = D_px / T`` exactly (T output pixels per
    micro-image pitch). ``q_paper`` is the paper's ``D' sin45 / N``; the views were cut
    at the converter's ``q`` (equal unless convert.view_spacing_px overrides it).
    ``s`` and the signed ``t`` follow the MLA kind (:func:`sensor_distance`,
    :func:`sharp_distance`; module docstring): for a Galilean MLA ``t < 0``, so
    ``C = (e + t) tan(beta)`` is small and may be negative (diverging views,
    ``X_c < 0``); ``X_c`` is infinite when the views are parallel."""
    p = ds.pixel_size
    P = o.multiview_pixel_size(p, conv.pitch_px, conv.tile)
    F = o.main_lens_focal(F_m, P)
    F_n = o.middle_f_number(ds.f_numbers)
    f = o.microlens_focal(F_n, ds.mla_pitch)
    s = ds.sensor_distance if ds.sensor_distance is not None else sensor_distance(ds.k, f,
                                                                                   conv.mla)
    e = o.focus_shift(F, ds.focus_distance)
    t = sharp_distance(s, f, conv.mla)
    q_paper = o.view_spacing(conv.safe_diameter_px, n_views)
    q_px = conv.q
    q = q_px * p
    beta = o.ray_angle(q, s)
    B = o.baseline(F, beta)
    C = o.convergence_offset(e, t, beta)
    alpha = o.rotation_angle(C, F)
    X_c = o.convergence_distance(B, alpha) if C != 0 else math.inf
    X_n = o.object_distance(B, F, C, conv.d_max, P)
    X_f = o.object_distance(B, F, C, conv.d_min, P)
    return {
        "p": p, "P": P, "P_sensor_ratio": p * ds.sensor_width / conv.width, "F_m_px": F_m,
        "F": F, "F_n": F_n, "D": ds.mla_pitch, "f": f, "k": ds.k, "s": s, "e": e, "t": t,
        "D_px": conv.pitch_px, "D_safe_px": conv.safe_diameter_px, "T": conv.tile,
        "q_px": q_px, "q_paper_px": q_paper, "q": q, "beta": beta, "B": B, "C": C,
        "alpha": alpha, "X_c": X_c, "X_o": ds.focus_distance, "N": n_views,
        "D_min_px": conv.d_min, "D_max_px": conv.d_max, "X_n": X_n, "X_f": X_f,
    }


def inverse_check(sym: Mapping, near: float | None, far: float | None, B_model: float,
                  alpha_model: float, tolerance: float = 0.05) -> dict:
    """Eqs. 2-3: B and alpha from the MEASURED X_n/X_f and the disparities, against a
    model's B and alpha (mm, rad).

    B passes when its relative difference is within ``tolerance``. Alpha is compared as
    the principal-point shift per view step it makes, ``pp_shift_diff_px = F_m (tan
    alpha_model - tan alpha_eq3)``, and passes within ``tolerance`` of the larger of the
    two terms Eq. 3 subtracts, ``F_m tan(alpha_eq3)`` and the near disparity
    ``D_max`` (``alpha_scale_px``): Eq. 3's alpha is only as good as ``D_max``. For a
    Keplerian camera ``|F_m tan alpha| > |D_max|`` (the views converge in front of the
    scene), so this is the relative test on alpha; a Galilean camera's views converge
    metres behind the scene: alpha is small against ``D_max`` (0.9 px against 6 px in
    the tiny set-up) and its relative difference would fail a correct model on a 1 %
    error of the measured disparity range (``rel_diff_alpha`` stays in the result)."""
    if near is None or far is None:
        return {"verdict": "skipped", "reason": "camera.yaml gives no scene.near_mm/far_mm"}
    P, F, F_m = sym["P"], sym["F"], sym["F_m_px"]
    if sym["D_max_px"] == sym["D_min_px"]:
        return {"verdict": "skipped", "reason": "D_max equals D_min: no depth range measured"}
    B2 = o.baseline_from_range(P, sym["D_max_px"], sym["D_min_px"], F, near, far)
    a3 = o.alpha_from_range(B2, F, near, sym["D_max_px"], P)
    rel_B = B_model / B2 - 1.0
    rel_a = math.tan(alpha_model) / math.tan(a3) - 1.0 if a3 != 0 else float("inf")
    diff_px = F_m * (math.tan(alpha_model) - math.tan(a3))
    scale_px = max(abs(F_m * math.tan(a3)), abs(sym["D_max_px"]))
    ok = abs(rel_B) <= tolerance and abs(diff_px) <= tolerance * scale_px
    return {
        "X_n_measured": near, "X_f_measured": far,
        "B_eq2": B2, "alpha_eq3": a3, "B_model": B_model, "alpha_model": alpha_model,
        "rel_diff_B": rel_B, "rel_diff_alpha": rel_a, "tolerance": tolerance,
        "pp_shift_diff_px": diff_px, "alpha_scale_px": scale_px,
        "verdict": "pass" if ok else "fail",
    }


# ---------------------------------------------------------------------------
# The exact model
# ---------------------------------------------------------------------------


def exact_model(sym: Mapping) -> dict:
    """The view geometry that the optics of Fig. 2 give for this converter (mm, rad).

    Derivation (thin lenses, OpenCV camera axes, main lens at z = 0, MLA at distance
    ``L`` behind it, sensor ``s`` behind the MLA; :meth:`PlenopticOptics.chief_rays`).
    A micro-image centre ``m`` is the central projection of its lens centre ``c``
    from the main-lens centre: ``m = c (L + s) / L``. View (h, v) samples, in every
    micro image, the sensor point ``x = m + delta`` with the same offset ``delta``
    (``-h q p`` in x: the readout turns the image by 180 degrees). Its chief ray runs
    from ``x`` through ``c`` with slope ``(c - x) / s`` and reaches the main lens at::

        c + L (c - m - delta) / s = c + L (-c s / L - delta) / s = -L delta / s,

    a point that does not depend on the lens: every chief ray of one view passes
    through ONE point of the main-lens plane, which is the view's centre of
    projection (a thin lens does not move the point where a ray crosses it). So the
    views are not rotated; their centres lie on the main-lens plane, spaced

        B_e = L q_mm / s      (+x for +h, +y for +v),

    and after the main lens the slope of view (h, v)'s ray through its tile centre
    ``o_i`` is ``-c/L + delta (L - F) / (s F)``. The first term is the central view's
    pinhole with ``F_m = L T / D`` (so ``F_m P = L + s``, which gives ``L`` from
    registration A's focal length: ``L = F_m P - s``); the second is a constant
    direction offset, i.e. the principal point moves by

        F_m B_e / Z0 pixels per step (+x for +h, +y for +v),  Z0 = F L / (L - F),

    ``Z0`` being the distance of the plane conjugate to the MLA, where all views see a
    point at the same pixel (zero disparity). ``F`` is the true main-lens focal length:
    the lens images the focus plane ``X_o`` sharply ``t = s f/(s - f)`` in front of the
    MLA, i.e. at ``L - t``, so ``F = X_o (L - t) / (X_o + L - t)``.

    Galilean MLA: nothing above depends on the kind (a chief ray is the straight line
    from the sensor point through the lens centre either way; the micro images'
    orientation only changes which sensor points the OTHER pixels of a tile sample),
    provided ``s`` and the signed ``t < 0`` are the Galilean ones: the focus plane is
    imaged ``|t|`` behind the MLA, at ``L - t = L + |t|``. Then ``L < F + e``, ``Z0`` lies
    beyond the focus distance (the views converge behind the scene, positive
    disparities), or, when ``L < F``, ``Z0 < 0``: the views diverge and the
    principal-point shift and ``alpha_equivalent`` are negative.

    Relation to the paper: its ``B = F_paper tan(beta)`` uses ``F_paper = F_m P = L + s``
    where the centres are ``L tan(beta)`` apart, so ``B_paper / B_e = (L + s) / L``; its
    rotation ``alpha`` plays the role of the principal-point shift
    (``tan(alpha_e) = shift / F_m = B_e / Z0``): a view turned by ``alpha`` and a view
    with the principal point shifted by ``F_m tan(alpha)`` agree to first order in
    alpha. The exact disparity between neighbours is ``F_m B_e (1/X - 1/Z0)``, exactly
    Eq. 1 with ``B_e`` and ``alpha_e``; hence Eqs. 2-3 recover ``B_e`` and ``alpha_e``.
    """
    s, t, P, F_m, q = sym["s"], sym["t"], sym["P"], sym["F_m_px"], sym["q"]
    L = F_m * P - s
    X_o = sym["X_o"]
    if L <= max(t, 0.0):
        raise ValueError(f"exact model: main lens-MLA distance L = F_m P - s = {L:.4g} mm is "
                         f"not beyond the sharp image distance t = {t:.4g} mm (nor 0); is "
                         "registration A's focal length in multiview pixels?")
    F_true = X_o * (L - t) / (X_o + L - t)
    inv_Z0 = (L - F_true) / (F_true * L)  # 1 / Z0: < 0 where the views diverge
    Z0 = 1.0 / inv_Z0 if inv_Z0 != 0 else math.inf
    B_e = L * q / s
    pp_shift = F_m * B_e * inv_Z0
    alpha_e = math.atan(B_e * inv_Z0)
    X_n = X_f = None
    if sym["D_max_px"] != -pp_shift:
        X_n = F_m * B_e / (sym["D_max_px"] + pp_shift)
    if sym["D_min_px"] != -pp_shift:
        X_f = F_m * B_e / (sym["D_min_px"] + pp_shift)
    return {
        "L": L, "F_true": F_true, "e_true": L - t - F_true, "Z0": Z0, "B": B_e,
        "pp_shift_px": pp_shift, "alpha_equivalent": alpha_e, "X_n": X_n, "X_f": X_f,
        "views": "converge" if inv_Z0 > 0 else "diverge" if inv_Z0 < 0 else "parallel",
        "B_paper_over_B": sym["B"] / B_e,
        "alpha_paper_over_alpha": sym["alpha"] / alpha_e if alpha_e else None,
    }


# ---------------------------------------------------------------------------
# Views (Eq. 4) and the rig document
# ---------------------------------------------------------------------------


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
              model: str = "exact", tolerance: float = 0.05,
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


# ---------------------------------------------------------------------------
# Comparison with ground truth (one N x N set)
# ---------------------------------------------------------------------------


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    A = np.stack([x, np.ones_like(x)], axis=1)
    return float(np.linalg.lstsq(A, y, rcond=None)[0][0])


def set_geometry(views: Mapping[str, tuple[np.ndarray, np.ndarray]], n_views: int,
                 width: int, height: int) -> dict:
    """Baseline, principal-point-equivalent shift and alpha-equivalent of one set.

    ``views``: (K, pose relative to the central view, metres). The pp-equivalent of a
    view is the pixel where the central view's optical axis direction lands in it
    (K R^T (0, 0, 1)): the shifted principal point for the exact model,
    ``c + F_m tan(h alpha)`` for the paper's rotated views; its slope per step gives
    ``alpha_eq = atan(slope / f)``."""
    hs, vs, xs, ys, us, ws, fs = [], [], [], [], [], [], []
    cx0, cy0 = (width - 1) / 2.0, (height - 1) / 2.0
    for name, (K, M) in views.items():
        h, v = view_position(*parse_view(name), n_views)
        d = M[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        uvw = K @ d
        hs.append(h)
        vs.append(v)
        xs.append(M[0, 3])
        ys.append(M[1, 3])
        us.append(uvw[0] / uvw[2] - cx0)
        ws.append(uvw[1] / uvw[2] - cy0)
        fs.append(K[0, 0])
    hs, vs = np.array(hs, float), np.array(vs, float)
    Bx, By = _slope(hs, np.array(xs)), _slope(vs, np.array(ys))
    px, py = _slope(hs, np.array(us)), _slope(vs, np.array(ws))
    f = float(np.mean(fs))
    return {"B_x_m": Bx, "B_y_m": By, "B_m": (Bx + By) / 2, "pp_shift_x_px": px,
            "pp_shift_y_px": py, "pp_shift_px": (px + py) / 2, "focal_px": f,
            "alpha_equivalent": math.atan((px + py) / 2 / f)}


def compare_with_truth(rig: Mapping, truth: Mapping[str, PinholeCamera]) -> dict:
    """Compare a ``rig.json`` document with ground-truth cameras of one N x N set
    (``truth``: view name -> camera in any world frame, metres).

    Both sets are expressed relative to their central view. Reports the baseline,
    pp-equivalent shift and alpha-equivalent of each with relative errors, the RMSE
    of the view centres (mm) and the largest rotation difference (degrees)."""
    n = int(rig["n_views"])
    W, H = int(rig["width"]), int(rig["height"])
    centre = central_view(n)
    missing = sorted(set(view_names(n)) - set(truth))
    if missing:
        raise ValueError(f"ground truth lacks views {', '.join(missing)} of the {n}x{n} set")
    to_c = invert_pose(truth[centre].cam_to_world)
    gt = {k: (truth[k].K, to_c @ truth[k].cam_to_world) for k in view_names(n)}
    est = RigB(rig).view_poses()
    g_gt = set_geometry(gt, n, W, H)
    g_est = set_geometry(est, n, W, H)
    d_c = np.array([est[k][1][:3, 3] - gt[k][1][:3, 3] for k in view_names(n)])
    rot = [rotation_angle_deg(est[k][1][:3, :3], gt[k][1][:3, :3]) for k in view_names(n)]
    return {
        "truth": g_gt, "estimate": g_est,
        "rel_err_B": g_est["B_m"] / g_gt["B_m"] - 1.0,
        "rel_err_alpha": g_est["alpha_equivalent"] / g_gt["alpha_equivalent"] - 1.0
        if g_gt["alpha_equivalent"] else None,
        "err_pp_shift_px": g_est["pp_shift_px"] - g_gt["pp_shift_px"],
        "centre_rmse_mm": float(np.sqrt((d_c ** 2).sum(axis=1).mean()) * 1000.0),
        "rotation_max_deg": float(max(rot)),
    }
