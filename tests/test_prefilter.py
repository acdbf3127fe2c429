"""The lenslet frame's prefilter (plenocal.convert.prefilter): its formula, the optimum
that sets convert.blend.prefilter, and that views come nearer the truth with it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, plane_view, random_texture
from test_convert import small_optics

from plenocal.config import stage_defaults
from plenocal.convert.levels import render_source
from plenocal.convert.prefilter import (
    OPTIMAL_A,
    expected_error,
    prefilter,
    prefilter_kernel,
    prefilter_response,
)
from plenocal.convert.quality import view_quality
from plenocal.convert.render import RenderSettings
from plenocal.convert.shot import ConvertSettings, ShotConversion
from plenocal.grid import MicrolensGrid

W = np.linspace(0.01, np.pi, 200)  # angular frequencies up to the sensor's Nyquist


def test_kernel_and_response_by_hand():
    k = prefilter_kernel(0.1)
    assert k.tolist() == pytest.approx([-0.1, 1.2, -0.1])
    assert float(k.sum()) == pytest.approx(1.0)
    # P_a(w) = 1 + 2a (1 - cos w): 1 at w = 0, 1 + 4a at Nyquist, 1 + 2a at w = pi / 2
    assert prefilter_response(0.1, np.array([0.0, np.pi / 2, np.pi])) == pytest.approx(
        [1.0, 1.2, 1.4])
    # the kernel's DFT is its response
    x = np.zeros(64)
    x[[63, 0, 1]] = [-0.1, 1.2, -0.1]
    f = np.fft.rfft(x)
    w = 2 * np.pi * np.arange(len(f)) / 64
    assert f.real == pytest.approx(prefilter_response(0.1, w), abs=1e-12)


def test_expected_error_by_hand():
    # without the filter, at Nyquist: |1 - 2t - e^{i pi t}|^2 = (1 - 2t)^2 - 2 (1 - 2t)
    # cos(pi t) + 1, whose mean over t in [0, 1] is 1/3 - 2 (4 / pi^2) + 1 = 4/3 - 8/pi^2
    assert expected_error(0.0, np.array([np.pi]), np.array([1.0]), phases=4001) == \
        pytest.approx(4 / 3 - 8 / np.pi ** 2, rel=1e-6)
    # with it: P = 1 + 4a there, |P (1 - 2t) - e^{i pi t}|^2 has the mean
    # P^2 / 3 - 8 P / pi^2 + 1
    P = 1.4
    assert expected_error(0.1, np.array([np.pi]), np.array([1.0]), phases=4001) == \
        pytest.approx(P * P / 3 - 8 * P / np.pi ** 2 + 1, rel=1e-6)
    # a constant is read exactly with or without the filter
    assert expected_error(0.1, np.array([0.0]), np.array([1.0])) == pytest.approx(0.0)


@pytest.mark.parametrize("power", [0, 1, 2])  # flat, 1/f and 1/f^2 spectra
def test_the_default_is_the_least_expected_error(power):
    """OPTIMAL_A is where Eq. P1 is least, within 0.015, for each spectrum, and it cuts
    the error by more than a fifth against no filter."""
    spectrum = (W / np.pi) ** -power
    grid = np.linspace(0.0, 0.25, 51)
    errs = [expected_error(a, W, spectrum) for a in grid]
    best = float(grid[int(np.argmin(errs))])
    a = OPTIMAL_A
    assert best == pytest.approx(a, abs=0.015)
    assert expected_error(a, W, spectrum) < 0.8 * expected_error(0.0, W, spectrum)


def test_prefilter_keeps_flat_areas_and_is_exact_in_place():
    flat = np.full((40, 50, 3), 1234, np.uint16)
    assert np.array_equal(prefilter(flat, 0.1), flat)
    rng = np.random.default_rng(0)
    img = rng.integers(0, 4096, (40, 50, 3), dtype=np.uint16) << 4
    out = prefilter(img, 0.1)
    same = img.copy()
    assert prefilter(same, 0.1, in_place=True) is same
    assert np.array_equal(same, out)
    assert prefilter(img, 0.0) is img


def test_render_source_filters_after_the_shift():
    """16-bit data of 12 bits: shifted to the top of the word, then filtered (its
    rounding below the data's last bit); 8-bit data filtered in its own levels."""
    rng = np.random.default_rng(1)
    img = rng.integers(0, 4096, (30, 40), dtype=np.uint16)
    src, unit = render_source(img, 12, 0.1)
    want = prefilter(img.astype(np.float32) * 16, 0.1)
    assert np.abs(src.astype(np.float32) - np.clip(want, 0, 65535)).max() <= 0.5
    assert unit == pytest.approx(1 / (4095 * 16))
    img8 = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    src8, _ = render_source(img8, 8, 0.1)
    assert np.array_equal(src8, prefilter(img8, 0.1))


def test_views_come_nearer_the_ideal_view_with_the_prefilter():
    """A plane of known patch size (as test_views_match_the_ideal_view_of_the_plane), its
    ideal views read from the texture by Keys' cubic: every view with OPTIMAL_A nearer
    them than without."""
    calib = calib_for_optics(small_optics())
    grid = MicrolensGrid(calib, 400, 300)
    tex = random_texture(512, 1.5, 3)
    P = 6.5
    img = lenslet_from_patch_size(grid, P, tex)
    psnr = {}
    for a in (0.0, OPTIMAL_A):
        st = ConvertSettings(tile_size=6, even_size=False, render=RenderSettings(prefilter=a))
        shot = ShotConversion(img, calib, 5, st)
        L = shot.layout
        for r, c in ((2, 2), (0, 0), (4, 1)):
            ideal8 = plane_view(calib, L, P, tex, r, c, cv2.INTER_CUBIC)
            psnr[a, r, c] = view_quality(shot.view(r, c), ideal8, border=L.tile)["psnr_db"]
    a = OPTIMAL_A
    for r, c in ((2, 2), (0, 0), (4, 1)):
        assert psnr[a, r, c] > psnr[0.0, r, c] + 0.1, psnr


def test_the_default_is_the_least_expected_error_in_two_dimensions():
    """The separable filter on both axes, bilinear interpolation at a uniform phase in x
    and y, a flat 2-D spectrum: Eq. P1's 2-D form is lower at OPTIMAL_A than 0.05 either
    side."""
    n = 24
    t = (np.arange(n) + 0.5) / n
    w = np.linspace(0.05, np.pi, 24)

    def error(a: float) -> float:
        read = prefilter_response(a, w)[None, :] * ((1 - t)[:, None] + t[:, None] * np.exp(
            1j * w[None, :]))  # (phase, frequency) per axis
        truth = np.exp(1j * t[:, None] * w[None, :])
        e = (read[:, None, :, None] * read[None, :, None, :]
             - truth[:, None, :, None] * truth[None, :, None, :])
        return float(np.mean(np.abs(e) ** 2))

    a = OPTIMAL_A
    assert error(a) < error(a - 0.05) and error(a) < error(a + 0.05)
    assert error(a) < 0.8 * error(0.0)


def test_off_by_default_and_then_the_frame_as_it_is():
    """convert.blend.prefilter is 0 by default (the calibration leaned with it), and then
    the views sample the frame's own integers: the same views, to the bit, as before the
    filter existed."""
    assert stage_defaults("convert.blend")["prefilter"] == 0
    assert RenderSettings().prefilter == 0
    rng = np.random.default_rng(2)
    img8 = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    assert render_source(img8, 8)[0] is img8
    img16 = rng.integers(0, 4096, (30, 40), dtype=np.uint16)
    assert np.array_equal(render_source(img16, 12)[0], img16 << 4)
