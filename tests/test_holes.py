"""Pixels that no micro image sees from inside its rim (issue 33): their support, and the
fill that takes them from their supported neighbours (plenocal.convert.holes)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from synth.lenslets import calib_for_optics, lenslet_from_patch_size, random_texture
from test_convert import FIXED_TILE, small_optics

from plenocal.convert import ShotConversion
from plenocal.convert.holes import (
    LEVEL_SUPPORT,
    SLAB_MARGIN_PX,
    STRIP_ROWS,
    SUPPORT_FULL,
    SparseConfidence,
    fill_unsupported,
    push_pull,
    support_confidence,
    weak_box,
)
from plenocal.convert.render import render_view, view_weights
from plenocal.grid import MicrolensGrid


def test_support_confidence_by_hand():
    s = np.array([-0.001, 0.0, SUPPORT_FULL / 4, SUPPORT_FULL, 0.5], np.float32)
    assert support_confidence(s).tolist() == [0.0, 0.0, 0.25, 1.0, 1.0]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_fill_keeps_supported_pixels_and_takes_holes_from_their_neighbours(dtype):
    """Pixels with full support keep their bits; a hole in a region of one colour takes
    that colour; the notches along an edge of a horizontal ramp take the ramp's value of
    their column; a half-supported pixel lies halfway between its value and the fill."""
    top = 1.0 if dtype == np.float32 else float(np.iinfo(dtype).max)
    H, W = 120, 160
    x = np.linspace(0.1, 0.9, W, dtype=np.float32)
    ramp = np.repeat(x[None, :, None], H, axis=0) * np.array([1.0, 0.5, 0.25], np.float32)
    view = ramp * top
    if dtype != np.float32:
        view = np.rint(view)
    view = view.astype(dtype)
    conf = np.ones((H, W), np.float32)
    # notches along the bottom edge: triangles 6 rows deep, one every 20 columns
    for x0 in range(0, W, 20):
        for d in range(6):
            conf[H - 1 - d, x0 + d:x0 + 12 - d] = 0.0
    conf[40, 70] = 0.5  # one half-supported pixel inside
    bad = view.copy()
    bad[conf == 0.0] = 0  # what the floor's past-rim samples show: dark
    bad[40, 70] = 0
    out = fill_unsupported(bad.copy(), conf)
    assert np.array_equal(out[conf == 1.0], view[conf == 1.0])
    hole = conf == 0.0
    err = np.abs(out[hole].astype(np.float64) - view[hole].astype(np.float64)).max()
    assert err <= 0.01 * top, err  # the ramp's value: at most 1 % off
    # half the (dark) pixel, half the fill; the fill's mean at the next level holds the
    # pixel's own half weight too (the 5 x 5 kernel's centre: 14 %), so a little below
    v, got = view[40, 70].astype(np.float64), out[40, 70].astype(np.float64)
    assert (got >= 0.43 * v).all() and (got <= 0.5 * v + 0.01 * top).all(), (got, v)


def test_fill_reads_only_its_slab_and_leaves_a_fully_supported_view():
    """Rows farther than SLAB_MARGIN_PX from every hole do not enter the fill, and a view
    with full support everywhere comes back untouched (the same array, the same bits)."""
    rng = np.random.default_rng(3)
    view = rng.integers(0, 256, (200, 90, 3), dtype=np.uint8)
    conf = np.ones((200, 90), np.float32)
    assert fill_unsupported(view, conf) is view
    before = view.copy()
    fill_unsupported(view, conf)
    assert np.array_equal(view, before)
    conf[150:152, 10:20] = 0.0
    a = fill_unsupported(view.copy(), conf)
    other = view.copy()
    other[: 150 - SLAB_MARGIN_PX] = 255 - other[: 150 - SLAB_MARGIN_PX]
    b = fill_unsupported(other, conf)
    assert np.array_equal(a[150 - SLAB_MARGIN_PX:], b[150 - SLAB_MARGIN_PX:])
    assert not np.array_equal(a[150:152, 10:20], view[150:152, 10:20])


def _corner_shot(patch: float = 10.0) -> ShotConversion:
    calib = calib_for_optics(small_optics(480, 300))
    grid = MicrolensGrid(calib, 480, 300)
    img = lenslet_from_patch_size(grid, patch, random_texture(512, 1.5, 5))
    return ShotConversion(img, calib, 5, FIXED_TILE)


def test_support_is_the_weight_of_the_samples_inside_the_rim():
    """pixel_support: the blend's weight without the floor, by hand from the plan's
    offsets, tile weights and the radial weight formula; 0 exactly where every slot
    samples past the rim's end."""
    shot = _corner_shot()
    plan = shot.plan_for(0, 0)
    o = shot.layout.offset_image(0, 0)
    support = np.empty(plan.map_x.shape[1:], np.float32)
    view_weights(plan, 0, 0, support=support)
    s = shot.settings.render.for_reach(shot.blend_of(0, 0))
    half = shot.safe.diameter_px / 2.0
    rim = half - s.rim_px
    rho = np.hypot(plan.off_x + o[0], plan.off_y + o[1])
    radial = np.clip((rim - rho) / s.rim_ramp_px, 0.0, 1.0)
    radial *= np.clip(1.0 - (rho / half) ** 2, 0.0, 1.0) ** s.centre_power
    by_hand = (plan.tile_weight * radial).sum(axis=0)
    # the tables step the squared radius (256 entries): a few thousandths of the weight
    assert np.abs(support - by_hand).max() < 0.01
    past = (rho >= rim).all(axis=0)
    assert past.any()  # the corner view's edge has such pixels
    assert np.abs(support[past]).max() < 1e-6


def test_corner_views_edges_are_filled_from_their_neighbours():
    """The synthetic micro images are dark past their rim, and the vignetting gain there
    is large, so the floor's samples render the corner view's unsupported edge pixels
    far off their neighbours (the notches of real frames); the converter's views take
    them from their supported neighbours instead (within the range of the supported
    pixels around each), and leave every supported pixel as the blend made it."""
    shot = _corner_shot()
    for r, c in ((0, 0), (4, 4)):
        plan = shot.plan_for(r, c)
        support = np.empty(plan.map_x.shape[1:], np.float32)
        raw = render_view(plan, shot._render_source, r, c, shot._render_scale, support=support)
        raw8 = np.clip(np.rint(raw * 255.0), 0, 255).astype(np.uint8)
        if raw8.shape[2] == 1:
            raw8 = np.repeat(raw8, 3, axis=2)
        view = shot.view(r, c)
        zero = support <= 0.0
        full = support >= SUPPORT_FULL
        assert zero.sum() >= 3, (r, c)
        assert np.array_equal(view[full], raw8[full])
        outside_raw = outside_view = 0
        for y, x in zip(*np.nonzero(zero), strict=True):
            win = (slice(max(y - 4, 0), y + 5), slice(max(x - 4, 0), x + 5))
            near = raw8[win][full[win]].astype(int)
            lo, hi = near.min(axis=0) - 2, near.max(axis=0) + 2
            outside_raw += bool(((raw8[y, x] < lo) | (raw8[y, x] > hi)).any())
            outside_view += bool(((view[y, x] < lo) | (view[y, x] > hi)).any())
        assert outside_view == 0, (r, c)
        assert outside_raw >= 0.3 * zero.sum(), (r, c, outside_raw, int(zero.sum()))


def test_boxes_band_by_band_give_the_same_fill_as_the_whole_confidence():
    """The renderer keeps, band by band, only the box of each band's weak pixels
    (weak_box); the fill from those boxes is the fill from the whole confidence map."""
    rng = np.random.default_rng(5)
    H, W = 150, 130
    view = rng.integers(0, 65536, (H, W, 3), dtype=np.uint16)
    support = np.full((H, W), 0.5, np.float32)
    support[H - 7:, :40] = 0.0  # a notch row along the bottom edge
    support[:, W - 3:] = 0.004  # a weak strip along the right edge
    support[60, 70] = 0.002  # one weak pixel inside
    boxes = []
    for y in range(0, H, 16):
        box = weak_box(support[y:y + 16])
        if box is not None:
            boxes.append((y + box[0], box[1], box[2]))
    assert weak_box(support[16:32, :100]) is None
    whole = fill_unsupported(view.copy(), support_confidence(support))
    assert np.array_equal(fill_unsupported(view.copy(), boxes), whole)
    assert not np.array_equal(whole, view)


def test_scattered_weak_pixels_are_kept_sparse_and_give_the_same_fill():
    """A band whose weak pixels are under half its box is kept as their indices and
    confidences (SparseConfidence: 8 bytes a weak pixel, not 4 a pixel of the box: on a
    frame whose lenses are mostly filled, every band's box spans the view); the fill from
    sparse, dense and mixed boxes is the fill from the whole confidence map, to the bit."""
    rng = np.random.default_rng(8)
    H, W = 160, 150
    view = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    support = np.full((H, W), 0.5, np.float32)
    support[3:96:7, 2::5] = rng.uniform(0.0, SUPPORT_FULL, (len(range(3, 96, 7)),
                                                            len(range(2, W, 5))))
    support[100:108, 20:30] = 0.0  # a dense hole, alone in its band
    boxes = []
    for y in range(0, H, 16):
        box = weak_box(support[y:y + 16])
        if box is not None:
            boxes.append((y + box[0], box[1], box[2]))
    sparse = [c for _, _, c in boxes if isinstance(c, SparseConfidence)]
    dense = [c for _, _, c in boxes if not isinstance(c, SparseConfidence)]
    assert sparse and dense
    for c in sparse:  # only the pixels below 1, each below 1
        assert (c.vals < 1.0).all() and c.idx.dtype == np.int32
    conf = support_confidence(support)
    whole = fill_unsupported(view.copy(), conf)
    assert np.array_equal(fill_unsupported(view.copy(), boxes), whole)
    assert not np.array_equal(whole[conf < 1.0], view[conf < 1.0])


def _push_pull_whole(img: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The push-pull of the module docstring on whole arrays, each level at once: what
    push_pull computed before it worked in strips."""
    if float(c.max()) <= 0.0:
        return img.copy()
    nums, dens = [img * c[..., None]], [c]
    while min(dens[-1].shape) > 1 and (len(dens) == 1 or float(dens[-1].min()) < LEVEL_SUPPORT):
        y = cv2.pyrDown(nums[-1])
        nums.append(y.reshape(y.shape[0], y.shape[1], img.shape[2]))
        dens.append(cv2.pyrDown(dens[-1]))
    d = dens[-1]
    mean = nums[-1].sum(axis=(0, 1)) / max(float(d.sum()), 1e-30)
    est = nums[-1] / np.maximum(d, np.float32(1e-12))[..., None]
    est[d <= 0] = mean
    for lv in range(len(nums) - 2, -1, -1):
        h, w = dens[lv].shape
        up = cv2.pyrUp(est, dstsize=(w, h)).reshape(h, w, img.shape[2])
        if lv == 0:
            a, v = c, img
        else:
            a = np.minimum(dens[lv] * np.float32(1.0 / LEVEL_SUPPORT), np.float32(1.0))
            v = nums[lv] / np.maximum(dens[lv], np.float32(1e-12))[..., None]
        est = a[..., None] * v + (1.0 - a[..., None]) * up
    return est


@pytest.mark.parametrize("shape", [(2 * STRIP_ROWS + 45, 97, 3), (STRIP_ROWS + 1, 64, 1),
                                   (9, 300, 3), (1, 50, 3), (300, 1, 3), (2, 2, 3)])
def test_push_pull_in_strips_gives_the_whole_pyramids_bits(shape):
    """push_pull makes its finest level in strips of STRIP_ROWS rows (the level's products
    and OpenCV's pyrDown / pyrUp with the rows their 5-tap kernels reach), so that a fill
    never holds a view-sized float array: the same bits as the pyramid of whole arrays, at
    odd heights and widths, one channel or three, a row or a column alone, and with holes
    wider than a strip."""
    rng = np.random.default_rng(sum(shape))
    img = rng.random(shape, dtype=np.float32) * 255
    c = rng.random(shape[:2], dtype=np.float32)
    c[c < 0.3] = 0.0
    c[c > 0.8] = 1.0
    if shape[0] > STRIP_ROWS:
        c[10:STRIP_ROWS + 20, 5:40] = 0.0  # a hole across a strip's edge
    np.testing.assert_array_equal(push_pull(img, c), _push_pull_whole(img, c))
    zero = np.zeros(shape[:2], np.float32)
    np.testing.assert_array_equal(push_pull(img, zero), img)
