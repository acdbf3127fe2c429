"""The micro-image centres found by the corner views' agreement (issue 33:
plenocal.convert.centring), where the grid check cannot confirm calib.xml's grid."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture

from plenocal.convert import ConvertSettings, ShotConversion
from plenocal.convert.centring import MIN_GAIN, MIN_SHIFT_PX, measure_centring, shifted_grid
from plenocal.convert.gridcheck import UNVERIFIED_USE, GridCheck
from plenocal.convert.setup import centred_lattice, centring_for, lattice_grid
from plenocal.grid import MicrolensGrid
from plenocal.optics import PlenopticOptics

SETTINGS = ConvertSettings(tile_size=6, even_size=False, mla="keplerian")


def _frame():
    """(calib, image): the default simulated camera on a small sensor, every patch 6 px,
    micro images with a dark rim past the file's D' (tests/synth/lenslets.py), blurred
    by a Gaussian of 1 px as a real frame's micro images are at their rims (the hard
    discs of the synthetic frame leave the corner views little to disagree on: a ripple
    of 2-3 % with the lattice's sub-pixel phase, where a real rim gives 25 % or more)."""
    opt = PlenopticOptics(focal_length=0.035, focus_distance=0.6, mla_pitch=130e-6,
                          mla_f_number=2.8, k=5.0, pixel_size=5.5e-6, width=480, height=320)
    calib = calib_for_optics(opt)
    grid = MicrolensGrid(calib, 480, 320)
    img = lenslet_from_patch_size(grid, 6.0, random_texture(512, 1.5, 3))
    return calib, cv2.GaussianBlur(img, (0, 0), 1.0)


def _moved(calib, dx: float, dy: float):
    """``calib`` whose grid lies (dx, dy) image px from the micro images (the file's
    offset is y-up: grid.py)."""
    return replace(calib, offset=(calib.offset[0] + dx, calib.offset[1] - dy))


def test_a_right_grid_is_left_where_it_is():
    calib, img = _frame()
    fit = measure_centring(ShotConversion(img, calib, 5, SETTINGS))
    assert np.hypot(*fit.offset_px) < MIN_SHIFT_PX, fit
    assert not fit.applied


@pytest.mark.parametrize("dx, dy", [(1.5, -2.0), (-2.5, -0.75)])
def test_the_corner_views_find_a_grid_moved_off_the_micro_images(dx, dy):
    """A calib.xml whose lattice lies (dx, dy) off the micro images: the search moves it
    back to within a quarter of a pixel, and the disagreement falls by half or more."""
    calib, img = _frame()
    fit = measure_centring(ShotConversion(img, _moved(calib, dx, dy), 5, SETTINGS))
    assert fit.applied, fit
    assert abs(fit.offset_px[0] + dx) <= 0.25 and abs(fit.offset_px[1] + dy) <= 0.25, fit
    assert fit.gain >= 0.5 > MIN_GAIN
    # the moved grid is the true one, lens for lens
    true = MicrolensGrid(calib, 480, 320)
    moved = shifted_grid(MicrolensGrid(_moved(calib, dx, dy), 480, 320), fit.offset_px)
    assert np.abs(moved.origin - true.origin).max() <= 0.25
    assert np.array_equal(moved.A, true.A)


def _check(**kw) -> GridCheck:
    base = dict(width=480, height=320, diameter_px=23.9, lenses=100, measured=5,
                measured_share=0.05, lit=100, lit_share=0.05, judged_drift_px=9.0,
                judged_stderr_px=3.0, fitted=True, drift_max_px=9.0, drift_rms_px=5.0,
                drift_stderr_px=3.0, regions={}, offset_px=(5.0, 5.0), pitch_ratio=1.0,
                rotation_deg=0.0, affine=[[1, 0], [0, 1]], origin=(0.0, 0.0),
                A=[[1, 0], [0, 1]], similarity_origin=(0.0, 0.0), residual_rms_px=3.0,
                similarity_residual_rms_px=3.0, foreign=False, refine_auto=False,
                verified=False,
                warnings=[f"grid check: only 5% of the 100 lit lenses measured: ... "
                          f"(fitted drift 9.0 px); {UNVERIFIED_USE}. Either ..."])
    return GridCheck(**{**base, **kw})


def test_only_an_unverified_auto_grid_is_searched():
    """convert.grid auto on a check that could not confirm the file's grid: searched,
    recorded in the check, and its warning says what the views use. A verified, foreign
    or refined check, or convert.grid file, is left alone (so every frame whose grid the
    check confirms, and every simulated capture, converts to the same bytes)."""
    calib, img = _frame()
    shot = ShotConversion(img, _moved(calib, 2.0, 1.0), 5, SETTINGS)
    for check, mode in ((_check(verified=True), "auto"), (_check(foreign=True), "auto"),
                        (_check(refined=True), "auto"), (_check(), "file")):
        assert centring_for(check, mode, shot, "x") is None
        assert check.centring is None and "centring" not in check.to_dict()
    check = _check()
    fit = centring_for(check, "auto", shot, "x")
    assert fit is not None and fit.applied
    assert check.centring == fit.to_dict() and check.to_dict()["centring"]["applied"]
    assert UNVERIFIED_USE not in check.warnings[0]
    assert "the views use it" in check.warnings[0]
    # the set-up's lattice: the file's moved, rounded, and its grid the same lenses
    grid = MicrolensGrid(_moved(calib, 2.0, 1.0), 480, 320)
    lattice = centred_lattice(grid, fit)
    again = lattice_grid(_moved(calib, 2.0, 1.0), 480, 320, lattice)
    assert np.allclose(again.origin, grid.origin + np.array(fit.offset_px), atol=1e-4)
    assert np.allclose(again.A, grid.A, atol=1e-6)
