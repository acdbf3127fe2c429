"""The compiled pieces of the plane sweep and SGM (plenocal/depth/costkernels.py and the
SGM aggregation) give the bits of the numpy / OpenCV definitions they replaced: the tad
cost, the best-k mean, the label-axis block move and the fused horizontal path pair; the
uncovered-window mask of the plane sweep is checked by hand and against the box filter
of the warped coverage channel that SGM keeps."""

import cv2  # (before pycolmap)
import numpy as np
from synth.costs import random_costs

from plenocal.depth.costkernels import (
    COVERED,
    mask_box_uncovered,
    mask_uncovered,
    mean_of_best,
    tad_pixels,
    tad_pixels_cover,
)
from plenocal.depth.planesweep import _box
from plenocal.depth.sgm import SgmOptions, _aggregate_dir, _to_label_axis, sgm_aggregate


def _features(rng, shape):
    """Grey, gradients and a coverage channel with 0, 1 and bilinear-border values."""
    f = rng.random((*shape, 4), np.float32)
    f[..., 1:3] = (f[..., 1:3] - 0.5) * np.float32(0.1)  # gradients: small, signed
    cover = np.ones(shape, np.float32)
    cover[:, :5] = 0.0
    cover[:, 5] = np.float32(0.29998779)
    cover[:3] = 0.0
    f[..., 3] = cover
    return np.ascontiguousarray(f)


def test_tad_pixels_is_the_numpy_definition():
    rng = np.random.default_rng(0)
    ref, warped = _features(rng, (13, 17)), _features(rng, (13, 17))
    warped[2:6, 3:9, 0] = ref[2:6, 3:9, 0]  # exact matches: zero differences
    diff = cv2.absdiff(ref, warped)
    want = np.minimum(diff[..., 0], np.float32(0.08))
    want /= np.float32(0.08)
    dg = np.add(diff[..., 1], diff[..., 2])
    np.minimum(dg, np.float32(0.04), out=dg)
    dg /= np.float32(0.04)
    want *= np.float32(0.3)
    dg *= np.float32(0.7)
    want += dg
    dc = np.empty((13, 17), np.float32)
    tad_pixels(ref, warped, dc)
    assert dc.tobytes() == want.tobytes()
    # SGM's variant: the same costs, and the coverage channel copied out
    dc2, cover = np.full((13, 17), np.nan, np.float32), np.full((13, 17), np.nan, np.float32)
    tad_pixels_cover(ref, warped, dc2, cover)
    assert dc2.tobytes() == want.tobytes()
    assert cover.tobytes() == np.ascontiguousarray(warped[..., 3]).tobytes()


def test_mask_box_uncovered_is_the_box_threshold():
    """SGM's test (plenocal.depth.sgm): the box-filtered warped coverage channel <= 0.999."""
    rng = np.random.default_rng(1)
    cover = _features(rng, (13, 17))[..., 3].copy()
    cost = rng.random((13, 17), np.float32)
    box = _box(cover, 5)
    want = cost.copy()
    np.copyto(want, np.float32(np.inf), where=box <= 0.999)
    mask_box_uncovered(box, cost)
    assert cost.tobytes() == want.tobytes()
    assert np.isinf(cost[:, :4]).all() and np.isfinite(cost[6:, 10:]).all()
    assert COVERED == np.float32(0.999)


def _box_cover_mask(hom, src_w, src_h, shape, window):
    """The mask as it was made until issue 15: a channel of ones warped like the source
    (bilinear, zero outside), box-filtered over the window (mirrored borders), <= 0.999."""
    ones = np.ones((src_h, src_w), np.float32)
    warped = cv2.warpPerspective(ones, hom, (shape[1], shape[0]),
                                 flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return _box(warped, window) <= 0.999


def test_mask_uncovered_by_hand():
    # a shift by (+2.5, -1) px: reference pixel (x, y) samples the source at (x + 2.5, y - 1)
    hom = np.array([[1.0, 0.0, 2.5], [0.0, 1.0, -1.0], [0.0, 0.0, 1.0]])
    cost = np.zeros((8, 10), np.float32)
    mask_uncovered(hom, 10.0, 8.0, 1, cost)
    bad = np.isinf(cost)
    # 3 x 3 windows: row y needs rows y-1..y+1 (mirrored: 0..1 at y = 0) at y - 1 >= 0 -> y >= 2
    # (row 1's window holds row 0, which samples v = -1); columns x-1..x+1 at u <= 9 ->
    # x + 1 + 2.5 <= 9 -> x <= 5 (x = 9's window is 8..9 mirrored)
    want = np.ones((8, 10), bool)
    want[2:, :6] = False
    assert (bad == want).all()


def test_mask_uncovered_agrees_with_the_box_of_a_warped_coverage_channel():
    rng = np.random.default_rng(1)
    H, W = 41, 57
    for trial in range(20):
        a = rng.normal(0, 0.02, (3, 3))
        a[2, :2] = rng.normal(0, 2e-4, 2)
        hom = np.eye(3) + a
        hom[:2, 2] = rng.uniform(-9, 9, 2) + 0.37  # off the 1/32 px grid of OpenCV's warp
        for window in (3, 7):
            cost = np.zeros((H, W), np.float32)
            mask_uncovered(hom, float(W), float(H), window // 2, cost)
            want = _box_cover_mask(hom, W, H, (H, W), window)
            # the two differ only where a window pixel lies within ~1/50 px of the border
            assert (np.isinf(cost) != want).mean() < 0.01, trial
            assert np.isinf(cost).any() and np.isfinite(cost).any()


def test_mask_uncovered_behind_the_source():
    # w = 1 - 0.1 x: columns x >= 10 map behind the source (w <= 0)
    hom = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-0.1, 0.0, 1.0]])
    cost = np.zeros((5, 20), np.float32)
    mask_uncovered(hom, 1000.0, 1000.0, 0, cost)
    assert np.isinf(cost[:, 10:]).all()


def test_mean_of_best_sums_the_k_smallest_ascending():
    per = random_costs((7, 9, 11), 0)
    ascending = np.sort(per, axis=0)
    for k in range(1, 8):
        out = np.empty(per.shape[1:], np.float32)
        mean_of_best(per.copy(), k, out)
        # k == S: the sources' own order (nothing sorted)
        planes = ascending if k < per.shape[0] else per
        want = planes[0].copy()
        for p in planes[1:k]:
            want += p
        want /= np.float32(k)
        assert out.tobytes() == want.tobytes(), k


def test_to_label_axis_moves_a_block_into_the_label_axis():
    rng = np.random.default_rng(2)
    vol = rng.random((5, 6, 40), np.float32)
    want = vol.copy()
    block = rng.random((16, 5, 6), np.float32)
    want[:, :, 20:36] = block.transpose(1, 2, 0)
    _to_label_axis(block, vol, 20)
    assert vol.tobytes() == want.tobytes()


def test_sgm_aggregate_adds_the_directions_in_turn():
    """The fused horizontal pair: the bits of each direction added onto zeros in turn."""
    rng = np.random.default_rng(3)
    cost = rng.random((9, 12, 7), np.float32)
    grey = rng.random((9, 12), np.float32)
    opt = SgmOptions()
    pen = (np.float32(opt.p1), np.float32(opt.p2), np.float32(opt.edge_contrast))
    want = np.zeros_like(cost)
    for dy, dx in [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)]:
        _aggregate_dir(cost, grey, dy, dx, *pen, want)
    assert sgm_aggregate(cost, grey, opt).tobytes() == want.tobytes()
