"""Registration B, the exact model: the view geometry that the optics of the paper's
Fig. 2 give for this converter (thin lenses, chief rays), computed from the paper's
symbols (:func:`plenocal.calib.reg_b.paper_model.paper_symbols`). The views are not
rotated: their centres lie on the main-lens plane, spaced ``B_e = L q / s``, and the
principal point moves per view step (derivation in :func:`exact_model`).

Units: lengths in millimetres and angles in radians.
"""

from __future__ import annotations

import math
from collections.abc import Mapping


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

