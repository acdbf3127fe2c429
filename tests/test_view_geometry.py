"""The views' geometry against true cameras with no adjustment (plenocal.verify.view_geometry):
renders of one fronto-parallel textured plane at a known depth, by cameras whose focal
length is scaled by a known amount, read against the unscaled ones."""

import itertools

import cv2
import numpy as np
import pytest
from synth.scenes import default_scene, make_plane, render

from plenocal.camera import PinholeCamera, intrinsics, pose
from plenocal.verify import view_geometry as vg

F, W, H, Z = 400.0, 320, 240, 0.6
F_WIDE = 300.0


def _cam(f: float, R: np.ndarray, centre, width: int = W, height: int = H) -> PinholeCamera:
    return PinholeCamera(intrinsics(f, (width - 1) / 2, (height - 1) / 2),
                         pose(R, np.asarray(centre, float)), width, height)


def _turn(deg_y: float, deg_x: float) -> np.ndarray:
    return (cv2.Rodrigues(np.array([0.0, np.radians(deg_y), 0.0]))[0]
            @ cv2.Rodrigues(np.array([np.radians(deg_x), 0.0, 0.0]))[0])


def _plane():
    texture = default_scene()[0].texture
    return [make_plane([0.0, 0.0, Z], 1.4, texture)]


def test_prediction_by_hand():
    """A point 0.1 m right of the axis at 1 m: 40 px right of view 1's centre; view 2,
    0.05 m to the right, sees it 20 px right of its centre; 10 % more focal, 22 px."""
    c1 = _cam(F, np.eye(3), [0, 0, 0])
    c2 = _cam(F, np.eye(3), [0.05, 0, 0])
    uv = np.array([[c1.K[0, 2] + 40.0, c1.K[1, 2]]])
    assert np.allclose(vg.predict(c1, c2, uv, np.array([1.0])), [[c2.K[0, 2] + 20.0,
                                                                  c2.K[1, 2]]])
    # 40 px at f = 440 is 0.0909 m; view 2 sees 0.0409 m at 440 px per metre: 18 px
    assert np.allclose(vg.predict(c1, c2, uv, np.array([1.0]), eps=0.1),
                       [[c2.K[0, 2] + 440.0 * (40.0 / 440.0 - 0.05), c2.K[1, 2]]])


def _magnification_read(eps_true: float) -> dict:
    """Four wide views (480 x 360 px at f = 300 px) of the plane, turned 6-12 deg from one
    another, rendered at ``F_WIDE (1 + eps_true)`` and read against ``F_WIDE``: every
    ordered pair's patches every 6 px."""
    scene = _plane()
    w, h = 480, 360
    truth = [_cam(F_WIDE, R, c, w, h) for R, c in (
        (np.eye(3), [0, 0, 0]), (_turn(10, 4), [0.03, -0.01, 0]),
        (_turn(-8, -6), [-0.02, 0.02, 0.01]), (_turn(5, -9), [0.01, 0.03, -0.01]))]
    grey = [cv2.cvtColor(render(_cam(F_WIDE * (1 + eps_true), c.R, c.centre, w, h), scene),
                         cv2.COLOR_RGB2GRAY).astype(np.float32) for c in truth]
    ys, xs = np.mgrid[20:h - 20:6, 20:w - 20:6]
    uv = np.column_stack([xs.ravel(), ys.ravel()]).astype(float)
    pairs = []
    for i, j in itertools.permutations(range(len(truth)), 2):
        c1, c2 = truth[i], truth[j]
        # the plane's z-depth in view 1 (fronto-parallel at Z in the world)
        z = (Z - c1.centre[2]) / c1.rays(uv)[:, 2]
        pred = vg.predict(c1, c2, uv, z)
        found = vg.match_patches(grey[i], grey[j], uv, pred, search=8, min_peak=0.9)
        pairs.append((found - pred, (vg.predict(c1, c2, uv, z, eps=1e-4) - pred) / 1e-4))
    return vg.focal_scale(pairs)


def test_a_magnified_view_set_reads_its_magnification():
    """Views rendered at the cameras' focal length read about 0, and 0.4 % above it about
    +0.4 % (within 0.15 %: the pairs' turns, 6-12 deg, carry the magnification; a
    magnification the same in both views of a pair is otherwise a shift, which the fit
    removes)."""
    same, more = _magnification_read(0.0), _magnification_read(0.004)
    assert same["patches"] > 10000 and more["patches"] > 10000
    assert abs(same["eps_robust_pct"]) < 0.15, same
    assert abs(more["eps_robust_pct"] - 0.4) < 0.15, more
    assert more["eps_pct"] - same["eps_pct"] == pytest.approx(0.4, abs=0.15)


def test_parallax_ratio_of_shortened_offsets():
    """Offsets 2 % of the predicted shift against it: ratio -0.02 along x; y carries no
    parallax (NaN)."""
    rng = np.random.default_rng(0)
    inv_z = rng.uniform(1.3, 2.3, 400)
    shift = np.column_stack([6.0 * inv_z, np.zeros(400)])
    offsets = np.column_stack([-0.02 * shift[:, 0] + 0.3, np.zeros(400)])
    rx, ry = vg.parallax_ratio(offsets, shift, inv_z)
    assert rx == pytest.approx(-0.02, abs=1e-9)
    assert np.isnan(ry)
    # no patch found: nothing to say
    assert all(np.isnan(vg.parallax_ratio(np.full((400, 2), np.nan), shift, inv_z)))
