"""Registration B, the paper's model (Section II-C, Eqs. 1-4): every symbol from the
datasheet, the converter's disparity range and registration A's ``F_m``, and the
inverse check of Eqs. 2-3 (B and alpha from the measured near / far distances).

Units: lengths in millimetres and angles in radians. Pixel centres at integer
coordinates.

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
from collections.abc import Mapping

from plenocal import optics as o
from plenocal.artifacts.disparity import Conversion
from plenocal.calib.reg_b.datasheet import Datasheet
from plenocal.viewgeom import MLA_KINDS


def sensor_distance(k: float, f: float, mla: str) -> float:
    """``s`` from the datasheet's ``k``: ``k f / (k - 1)`` for a Keplerian MLA (the paper),
    ``k f / (k + 1)`` for a Galilean one (sharp virtual plane ``k f`` behind the MLA)."""
    if mla == "galilean":
        if k <= 0:
            raise ValueError(f"camera.yaml: mla.k = {k}: must be > 0")
        return k * f / (k + 1.0)
    if k <= 1:
        raise ValueError(f"camera.yaml: mla.k = {k:g}: a Keplerian MLA (the converter's "
                         "disparity.json) needs k > 1 (s = k f / (k - 1)); k <= 1 is a "
                         "Galilean MLA's: check mla.k, or the dataset's mla kind")
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

