"""DIBR reproduces a view of a planar scene from two inputs; push-pull fills holes;
occluders win the z-test."""

import numpy as np
import pytest
from synth.planes import camera_at, fronto_plane, photo_texture, render_plane

from plenocal.camera import PinholeCamera
from plenocal.verify.dibr import DibrOptions, View, forward_depth, psnr, push_pull, synthesize

W, H, F = 320, 240, 500.0


@pytest.fixture(scope="module")
def texture():
    # little texel noise: two resamplings of pure per-texel noise are not what DIBR is
    # judged on (the depth tests use the noisier texture)
    return photo_texture(512, noise=0.005)


@pytest.mark.parametrize("tilt", [0.0, 30.0])
def test_dibr_planar_scene_two_inputs(texture, tilt):
    plane = fronto_plane(0.6, 0.8, texture, tilt)
    tgt = camera_at([0.0, 0.0, 0.0], F, W, H)
    ins = [camera_at([dx, 0.004, 0.0], F, W, H) for dx in (-0.02, 0.02)]
    truth, _ = render_plane(tgt, plane)
    views = [View(c, *render_plane(c, plane)) for c in ins]
    out, seen = synthesize(views, tgt)
    assert seen.mean() > 0.97  # the top rows lie outside both inputs
    assert psnr(out, truth, 8) > 35.0


def test_dibr_wrong_depth_is_worse(texture):
    plane = fronto_plane(0.6, 0.8, texture, 0.0)
    tgt = camera_at([0.0, 0.0, 0.0], F, W, H)
    ins = [camera_at([dx, 0.0, 0.0], F, W, H) for dx in (-0.02, 0.02)]
    truth, _ = render_plane(tgt, plane)
    views = [View(c, img, d * 1.05) for c in ins for img, d in [render_plane(c, plane)]]
    out, _ = synthesize(views, tgt)
    assert psnr(out, truth, 8) < 30.0


def test_forward_depth_of_plane_is_exact_for_fronto_plane(texture):
    plane = fronto_plane(0.6, 0.8, texture, 0.0)
    a, b = camera_at([0, 0, 0], F, W, H), camera_at([0.01, 0, 0], F, W, H)
    _, d = render_plane(a, plane)
    z = forward_depth(a, d, b)
    inner = z[20:-20, 20:-20]
    assert (inner > 0).all()
    np.testing.assert_allclose(inner, 0.6, rtol=1e-6)


def test_occluder_wins_z_test(texture):
    far_plane = fronto_plane(0.7, 1.0, texture, 0.0)
    tgt = camera_at([0, 0, 0], F, W, H)
    src = camera_at([0.01, 0, 0], F, W, H)
    img, d = render_plane(src, far_plane)
    img = img.copy()
    d = d.copy()
    img[100:140, 100:160] = [1.0, 0.0, 0.0]  # red square at 0.5 m
    d[100:140, 100:160] = 0.5
    out, _ = synthesize([View(src, img, d)], tgt)
    # the square moves by f * b / z = 10 px to the right in the target
    np.testing.assert_allclose(out[110:130, 115:165].mean(axis=(0, 1)), [1, 0, 0], atol=0.05)


def test_push_pull_fills_holes():
    v = np.zeros((16, 16), np.float32)
    w = np.zeros_like(v)
    v[:, :8], w[:, :8] = 1.0, 1.0
    out = push_pull(v, w)
    assert np.all(out[:, :8] == 1.0)
    assert np.all(np.isfinite(out)) and out[:, 8:].min() > 0.99


def test_push_pull_by_hand():
    """A 4 x 4 image known at two pixels: (0, 0) = 1 and (3, 3) = 0. The first push level
    (2 x 2 blocks) holds the means 1 and 0 in the diagonal blocks and nothing in the
    others; the top level holds (1 + 0) / 2. Pulling down, the empty blocks take the top's
    0.5 and each hole its own block's mean: a pyramid, not the mean of all known pixels
    (0.5 everywhere) nor the nearest known pixel."""
    v = np.zeros((4, 4, 3), np.float32)
    w = np.zeros((4, 4), np.float32)
    v[0, 0], w[0, 0] = (1.0, 0.25, 0.5), 1.0
    v[3, 3], w[3, 3] = (0.0, 0.75, 0.5), 1.0
    v[1, 2] = (9.0, 9.0, 9.0)  # a hole's value is never read
    out = push_pull(v, w)
    expected = np.empty_like(v)
    expected[:2, :2] = (1.0, 0.25, 0.5)
    expected[2:, 2:] = (0.0, 0.75, 0.5)
    expected[:2, 2:] = expected[2:, :2] = (0.5, 0.5, 0.5)
    np.testing.assert_array_equal(out, expected)
    # one level deeper: an 8 x 8 image known in its top-left 4 x 4 block alone (value 2)
    # and at (7, 7) (value 0): the top level's mean is (16 * 2 + 0) / 17 = 32 / 17, which
    # the two empty 4 x 4 blocks take; the bottom-right block's holes take the mean of
    # their own 2 x 2 block (0) where it has weight, else that block's 4 x 4 mean (0)
    v = np.zeros((8, 8), np.float32)
    w = np.zeros((8, 8), np.float32)
    v[:4, :4], w[:4, :4] = 2.0, 1.0
    w[7, 7] = 1.0
    out = push_pull(v, w)
    np.testing.assert_array_equal(out[:4, :4], 2.0)
    np.testing.assert_allclose(out[:4, 4:], 32 / 17, rtol=1e-6)
    np.testing.assert_allclose(out[4:, :4], 32 / 17, rtol=1e-6)
    np.testing.assert_array_equal(out[4:, 4:], 0.0)


def test_soft_z_test_keeps_near_input_against_distant_too_near_depth(texture):
    """A distant input whose depth is 4 % too near (as estimated depth is) must not
    replace the nearest input's correct samples: the soft z-test blends both (the
    nearer camera dominating); the hard 2 % band of ``z_tolerance`` lets it win."""
    plane = fronto_plane(0.6, 0.8, texture, 0.0)
    tgt = camera_at([0.0, 0.0, 0.0], F, W, H)
    near_cam, far_cam = camera_at([0.004, 0.0, 0.0], F, W, H), camera_at([-0.03, 0, 0], F, W, H)
    truth, _ = render_plane(tgt, plane)
    img_n, d_n = render_plane(near_cam, plane)
    img_f, d_f = render_plane(far_cam, plane)
    views = [View(near_cam, img_n, d_n), View(far_cam, img_f, d_f * 0.96)]
    soft, _ = synthesize(views, tgt)
    hard, _ = synthesize(views, tgt, DibrOptions(z_tolerance=0.02, depth_exponent=0.0))
    assert psnr(soft, truth, 16) > 33.0
    assert psnr(soft, truth, 16) > psnr(hard, truth, 16) + 5.0


def test_exactly_aligned_cameras_keep_the_background_beside_an_occluder(texture):
    """Issue 32: the ground-truth cameras of a row of views are exactly aligned (a point
    on a pixel row of the input projects onto the same row of the target). The rows just
    above and below an occluder's horizontal edges are background that the input sees:
    they must be rendered from it whatever the last bit of the projection, not lost behind
    a foreground splat reaching a whole pixel past the edge (then left to inpainting)."""
    far_plane = fronto_plane(0.7, 1.0, texture, 0.0)
    src = camera_at([0.01, 0, 0], F, W, H)
    img, d = render_plane(src, far_plane)
    img, d = img.copy(), d.copy()
    img[100:140, 100:160] = [1.0, 0.0, 0.0]  # a red square at 0.5 m
    d[100:140, 100:160] = 0.5
    base = camera_at([0, 0, 0], F, W, H)
    truth, _ = render_plane(base, far_plane)
    # the square spans columns 110-169 of the target (f b / z = 10 px); columns 115-165
    # of the rows beside it are background that the input sees
    for dy in (0.0, 1e-9, -1e-9):  # the same camera to round-off
        K = base.K.copy()
        K[1, 2] += dy
        tgt = PinholeCamera(K, base.cam_to_world, W, H)
        out, seen = synthesize([View(src, img, d)], tgt)
        for row in (99, 140):
            assert seen[row, 115:165].all(), (dy, row, np.flatnonzero(~seen[row, 115:165]))
            assert np.abs(out[row, 115:165] - truth[row, 115:165]).mean() < 0.02
