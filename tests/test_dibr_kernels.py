"""The DIBR's compiled kernels against the previous implementation
(tests/synth/dibr_previous.py, the DIBR before the ninth session's speed-up): the same
bits for the synthesized images, the seen masks and the PSNR, on scenes with holes in
the input depth, depth discontinuities, an occluder, pixel-boundary projections (an
integer disparity) and a rotated target, with every option; push-pull's pull of the
holes only against the full pull; the nearest aux lookup against cv2.remap."""

import cv2
import numpy as np
import pytest
from synth import dibr_previous as previous
from synth.planes import camera_at, fronto_plane, photo_texture, render_plane

from plenocal.camera import PinholeCamera, pose
from plenocal.verify.dibr import (
    DibrOptions,
    View,
    _nearest_index,
    forward_depth,
    psnr,
    push_pull,
    synthesize,
)

W, H, F = 200, 150, 300.0


@pytest.fixture(scope="module")
def scene():
    """Three inputs of a tilted plane with an occluding square nearer the cameras
    (its depth a discontinuity, the plane's border a hole in the depth)."""
    texture = photo_texture(256, noise=0.02)
    plane = fronto_plane(0.6, 0.5, texture, 20.0)
    views = []
    for centre in ([-0.02, 0.0, 0.0], [0.02, 0.003, 0.0], [0.004, -0.015, 0.0]):
        cam = camera_at(centre, F, W, H)
        img, d = render_plane(cam, plane)
        img, d = img.copy(), d.copy()
        img[60:90, 80:120] = [0.9, 0.2, 0.1]
        d[60:90, 80:120] = 0.45
        views.append(View(cam, img, d))
    return views


def _rotated_camera(centre, rvec) -> PinholeCamera:
    base = camera_at(centre, F, W, H)
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))
    return PinholeCamera(base.K, pose(R, np.asarray(centre, dtype=float)), W, H)


TARGETS = {
    "shifted": lambda: camera_at([0.003, 0.001, 0.0], F, W, H),
    # disparity f * b / z = 300 * 0.006 / 0.45 = 4 px exactly at the occluder
    "integer disparity": lambda: camera_at([-0.014, 0.0, 0.0], F, W, H),
    "rotated": lambda: _rotated_camera([0.001, 0.002, 0.001], [0.01, -0.02, 0.005]),
    # beyond the inputs: its border is seen by none (holes to fill)
    "outside": lambda: camera_at([-0.06, 0.03, 0.0], F, W, H),
}

OPTIONS = {
    "default": DibrOptions(),
    "hard z-test": DibrOptions(z_tolerance=0.02, depth_exponent=0.0),
    "linear, push-pull": DibrOptions(interpolation="linear", hole_fill="pushpull"),
    "no inpainting": DibrOptions(inpaint=False, edge_weight=0.0),
}


@pytest.mark.parametrize("target", list(TARGETS))
@pytest.mark.parametrize("option", list(OPTIONS))
def test_synthesize_matches_previous_implementation(scene, target, option):
    tgt, opt = TARGETS[target](), OPTIONS[option]
    out, seen = synthesize(scene, tgt, opt)
    ref, ref_seen = previous.synthesize(scene, tgt, opt)
    assert seen.mean() > 0.3
    assert target != "outside" or seen.mean() < 0.95
    np.testing.assert_array_equal(seen, ref_seen)
    assert out.dtype == ref.dtype and out.shape == ref.shape
    assert out.tobytes() == ref.tobytes()
    truth = render_plane(tgt, fronto_plane(0.6, 0.5, photo_texture(256, noise=0.02), 20.0))[0]
    assert psnr(out, truth, 9) == previous.psnr(ref, truth, 9)


def test_synthesize_matches_previous_implementation_grey(scene):
    grey = [View(v.camera, v.image.mean(axis=2), v.depth) for v in scene]
    tgt = TARGETS["rotated"]()
    out, seen = synthesize(grey, tgt)
    ref, ref_seen = previous.synthesize(grey, tgt)
    assert out.ndim == 2
    np.testing.assert_array_equal(seen, ref_seen)
    assert out.tobytes() == ref.tobytes()


def test_forward_depth_matches_previous_implementation(scene):
    for v in scene:
        for make in TARGETS.values():
            tgt = make()
            for depth in (v.depth, v.depth.astype(np.float64) * 1.0001):
                np.testing.assert_array_equal(forward_depth(v.camera, depth, tgt),
                                              previous.forward_depth(v.camera, depth, tgt))


@pytest.mark.parametrize("shape", [(37, 53, 3), (64, 64, 1), (1, 9, 3), (5, 1, 1), (16, 15)])
@pytest.mark.parametrize("holes", [0.0, 0.3, 0.97, 1.0])
def test_push_pull_matches_full_pull(shape, holes):
    rng = np.random.default_rng(len(shape) + int(100 * holes))
    v = rng.random(shape).astype(np.float32)
    w = (rng.random(shape[:2]) >= holes).astype(np.float32)
    w[: shape[0] // 2, : shape[1] // 3] = 0.0  # a large hole: several levels up
    out, ref = push_pull(v, w), previous.push_pull(v, w)
    assert out.shape == ref.shape
    assert out.tobytes() == ref.tobytes()


def test_nearest_index_is_cv2_remap_nearest():
    """cv2.remap(INTER_NEAREST, BORDER_CONSTANT) of a ramp tells which pixel it takes:
    halves round to even, off the image (and NaN, huge values) nothing."""
    Wa, Ha = 7, 5
    ramp = np.arange(1, Wa * Ha + 1, dtype=np.float32).reshape(Ha, Wa)
    rng = np.random.default_rng(3)
    u = np.concatenate([np.arange(-2.0, 9.0, 0.5), rng.uniform(-3, 10, 200),
                        [np.nan, np.inf, -np.inf, 1e6, -1e6, 40000.0, -0.5, -0.49999997,
                         6.4999995, 6.5]]).astype(np.float32)
    v = np.resize(np.concatenate([np.arange(-1.5, 6.0, 0.5), rng.uniform(-2, 7, 30)]),
                  u.shape).astype(np.float32)
    got = cv2.remap(ramp, u[None], v[None], cv2.INTER_NEAREST,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=0)[0]
    for ui, vi, g in zip(u, v, got, strict=True):
        ix, iy = _nearest_index(ui, Wa), _nearest_index(vi, Ha)
        expect = ramp[iy, ix] if ix >= 0 and iy >= 0 else 0.0
        assert expect == g, (ui, vi)
