"""The paper's optics formulas (Section II-C, Eqs. 1-4) against hand-computed values,
and the exact thin-lens model against first principles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plenocal import optics as o


def test_section_2c_chain_by_hand():
    # datasheet example: p = 5.5 um, D = 0.13 mm, F_n = 2.8, k = 5, X_o = 600 mm
    f = o.microlens_focal(2.8, 0.13)
    assert f == pytest.approx(0.364)
    s = o.mla_sensor_distance(5.0, f)
    assert s == pytest.approx(5 * 0.364 / 4)  # 0.455 mm
    t = o.sharp_image_distance(s, f)
    assert t == pytest.approx(1.82)  # = k f
    e = o.focus_shift(35.0, 600.0)
    assert e == pytest.approx(35.0 ** 2 / 565.0)  # 2.16814 mm
    P = o.multiview_pixel_size(0.0055, 23.9, 6.0)
    assert P == pytest.approx(0.0055 * 23.9 / 6.0)
    F = o.main_lens_focal(1800.0, P)
    assert F == pytest.approx(1800 * 0.0219083333, rel=1e-6)
    q = o.view_spacing(o.safe_diameter(23.9, 1.0), 5)
    assert q == pytest.approx(21.9 * math.sqrt(0.5) / 5)  # 3.0971 px
    beta = o.ray_angle(q * 0.0055, s)
    assert math.tan(beta) == pytest.approx(q * 0.0055 / 0.455)
    B = o.baseline(F, beta)
    assert B == pytest.approx(F * q * 0.0055 / 0.455)
    C = o.convergence_offset(e, t, beta)
    assert C == pytest.approx((e + t) * q * 0.0055 / 0.455)
    alpha = o.rotation_angle(C, F)
    assert math.tan(alpha) == pytest.approx(C / F)
    assert o.convergence_distance(B, alpha) == pytest.approx(B * F / C)


def test_eq1_and_its_inverse_eqs_2_3():
    B, F, C, P = 0.8, 40.0, 0.1, 0.02
    D_max, D_min = -3.0, -4.5
    X_n = o.object_distance(B, F, C, D_max, P)
    X_f = o.object_distance(B, F, C, D_min, P)
    assert X_n == pytest.approx(B * F / (C + D_max * P))
    assert X_n < X_f
    assert o.baseline_from_range(P, D_max, D_min, F, X_n, X_f) == pytest.approx(B)
    assert math.tan(o.alpha_from_range(B, F, X_n, D_max, P)) == pytest.approx(C / F)


def test_eq4_extrinsic():
    M = o.view_extrinsic(0, 0, 1.0, 0.01)
    np.testing.assert_allclose(M, np.eye(4))  # the central view: identity
    M = o.view_extrinsic(2, -1, 0.5, 0.01)
    np.testing.assert_allclose(M[:3, 3], [1.0, -0.5, 0.0])
    R = M[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    # a view right of centre looks slightly left (towards the centre): its optical
    # axis has a negative x component
    assert R[0, 2] < 0
    # a view above the centre (v < 0) looks slightly down: positive y component
    assert R[1, 2] > 0


def test_middle_f_number():
    assert o.middle_f_number([5.6, 2.8, 4.0]) == 4.0
    assert o.middle_f_number(2.8) == 2.8


def test_exact_model_against_first_principles():
    opt = o.PlenopticOptics(0.035, 0.6, 130e-6, 2.8, 5.0, 5.5e-6, 2048, 1536)
    # the focus plane is imaged t in front of the MLA: virtual depth k - 1
    assert opt.virtual_depth(0.6) == pytest.approx(4.0)
    assert opt.depth_from_virtual_depth(4.0) == pytest.approx(0.6)
    # just beyond the MLA-conjugate plane (virtual depth -> 0) the micro-image
    # disparity blows up; far away it tends to D s (1/(L - F) - 1/L) / p
    assert opt.virtual_depth(opt.mla_conjugate_distance) == pytest.approx(0.0, abs=1e-9)
    assert opt.micro_image_disparity_px(opt.mla_conjugate_distance * 1.001) > 100
    Z = 0.5
    a = opt.L - opt.image_distance(Z)
    # for a << L, disparity ~ micro-image pitch / virtual depth
    approx = opt.micro_image_pitch_px / opt.virtual_depth(Z)
    assert opt.micro_image_disparity_px(Z) == pytest.approx(approx, rel=0.06)
    assert opt.micro_image_disparity_px(Z) == pytest.approx(
        130e-6 * opt.s * (1 / a - 1 / opt.L) / 5.5e-6)


def test_chief_rays_of_a_view_meet_on_the_main_lens_plane():
    """Offsets measured from micro-image centres: every chief ray of one view offset
    crosses the main-lens plane at the same point, L * offset / s from the axis."""
    opt = o.PlenopticOptics(0.035, 0.6, 130e-6, 2.8, 5.0, 5.5e-6, 2048, 1536)
    pitch = opt.micro_image_pitch_px
    lens = np.array([[1023.5 + i * pitch, 767.5 + j * pitch * 0.866] for i in range(-30, 31, 6)
                     for j in range(-20, 21, 5)])
    off = np.array([3.1, -6.2])
    origins, dirs = opt.chief_rays(lens + off, lens)
    assert np.ptp(origins[:, 0]) < 1e-12 and np.ptp(origins[:, 1]) < 1e-12
    # +u on the sensor is -x in metric; the ray through the lens continues to +x
    expected = opt.L * off * opt.pixel_size / opt.s
    np.testing.assert_allclose(origins[0, :2], [expected[0], expected[1]], rtol=1e-9)
    # through the main-lens centre rays are undeviated: the central view's rays point
    # back through the micro-image centre
    o0, d0 = opt.chief_rays(lens, lens)
    np.testing.assert_allclose(o0, 0.0, atol=1e-15)
    xs, ys = opt.sensor_to_metric(lens[:, 0], lens[:, 1])
    back = -np.stack([xs, ys], axis=1) / (opt.L + opt.s)
    np.testing.assert_allclose(d0[:, :2] / d0[:, 2:], back, rtol=1e-9)


@pytest.mark.parametrize("bad", [
    lambda: o.mla_sensor_distance(1.0, 0.3),
    lambda: o.sharp_image_distance(0.3, 0.3),
    lambda: o.focus_shift(35.0, 30.0),
])
def test_impossible_optics_raise(bad):
    with pytest.raises(ValueError):
        bad()


def _thin_lens_blur_px(opt: o.PlenopticOptics, v: float, lens_type: int) -> float:
    """Blur disc from first principles: a point a = v s in front of a lens of focal f_i
    (a < 0: a virtual object behind it) images at b' (1/b' = 1/f_i - 1/a); a disc of
    the lens aperture D meets the sensor s behind the lens at D |s - b'| / b'."""
    a = v * opt.s
    b = 1.0 / (1.0 / opt.type_f(lens_type) - 1.0 / a)
    return opt.mla_pitch * abs(opt.s - b) / b / opt.pixel_size


@pytest.mark.parametrize("kind", ["keplerian", "galilean"])
def test_lens_types_blur_by_the_thin_lens_law(kind):
    opt = o.PlenopticOptics(0.035, 0.6, 130e-6, 2.8, 5.0, 5.5e-6, 2048, 1536, kind=kind,
                            type_focal_ratios=(0.94, 1.0, 1.068))
    sign = 1.0 if kind == "keplerian" else -1.0
    sharp = [1.0 / opt.type_kappa(i) for i in range(3)]
    # the middle type is the reference: sharp at the focus plane, v = k - 1 (Keplerian)
    # or -(k + 1) (Galilean: a virtual image behind the MLA)
    assert sharp[1] == pytest.approx(4.0 if kind == "keplerian" else -6.0)
    assert opt.virtual_depth(0.6) == pytest.approx(sharp[1])
    assert opt.t == pytest.approx(sign * 5.0 * opt.f)
    assert (opt.s < opt.f) == (kind == "galilean")
    for i in range(3):
        assert opt.type_t(i) / opt.s == pytest.approx(sharp[i])  # v_i = t_i / s
        assert opt.blur_px(sharp[i], i) == pytest.approx(0.0, abs=1e-9)
        for v in (2.5, 3.3, 4.7, 9.0):
            assert opt.blur_px(sign * v, i) == pytest.approx(
                _thin_lens_blur_px(opt, sign * v, i), rel=1e-9)
        lo, hi = opt.depth_of_field(i, 1.0)
        assert lo < abs(sharp[i]) < hi
        assert opt.blur_px(sign * lo, i) == pytest.approx(1.0)
        if math.isfinite(hi):
            assert opt.blur_px(sign * hi, i) == pytest.approx(1.0)
    # three different types, three different blurs of one depth
    blurs = [opt.blur_px(sign * 3.3, i) for i in range(3)]
    assert len({round(b, 6) for b in blurs}) == 3


def test_galilean_optics_share_the_chief_rays():
    """Chief rays do not see the microlens focal length: a Galilean camera with the same
    s and L has the same view geometry (its micro images are upright, not its views)."""
    kep = o.PlenopticOptics(0.035, 0.6, 130e-6, 2.8, 5.0, 5.5e-6, 2048, 1536)
    gal = o.PlenopticOptics(0.035, 0.6, 130e-6, 2.8, 5.0, 5.5e-6, 2048, 1536, kind="galilean")
    assert gal.L == pytest.approx(gal.focal_length + gal.e - 5.0 * gal.f)
    assert gal.aperture == pytest.approx(gal.mla_pitch * gal.L / gal.s)
    # beyond the focus plane the main-lens image moves towards the MLA: |v| shrinks
    assert gal.virtual_depth(0.74) < 0 and abs(gal.virtual_depth(0.74)) < 6.0
    assert gal.micro_image_disparity_px(0.5) < 0 < kep.micro_image_disparity_px(0.5)
    with pytest.raises(ValueError):
        o.PlenopticOptics(0.035, 0.6, 130e-6, 2.8, 5.0, 5.5e-6, 64, 64, kind="newtonian")
