"""The compiled renderer pieces (plenocal.slotkernels, plenocal.convert.renderkernels) give
the bits of the numpy and OpenCV chains they replaced, kept here as the oracles: the
nearest-slot sorting network over whole arrays, and the view as view_weights, slot_samples
(cv2.convertMaps, cv2.remap) and cv2.accumulateProduct made it."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from test_convert import calib_for_optics, patch6_shot, small_optics

from plenocal import viewgeom
from plenocal.convert.render import make_plans, render_view, slot_samples, view_weights
from plenocal.convert.vignetting import BIN_PX
from plenocal.io.raytrix import RayCalib


def numpy_nearest_slots(layout, keep, k, rows):
    """nearest_slots as numpy computed it before the compiled pass: per candidate a
    lookup, a squared distance and a uint32 key ``quantised d2 << 5 | candidate``, a
    sorting network of min / max passes over the slots, then a gather per slot."""
    table, cell, off = viewgeom._lattice_lookup(layout, k, rows)
    lens = np.empty((k + 1,) + cell.shape, np.int32)
    dist = np.empty(lens.shape, np.float32)
    lens[k], dist[k] = -1, np.inf
    bits = np.uint32(viewgeom._KEY_BITS)
    slots = []
    for n, o in enumerate(off):
        table.take(cell + o, out=lens[n])
        dist[n] = viewgeom._tile_dist2(layout, lens[n], rows)
        key = np.minimum(dist[n] * viewgeom._KEY_SCALE, viewgeom._KEY_MAX).astype(np.uint32)
        np.minimum(key, np.uint32(viewgeom._KEY_MAX), out=key)
        key <<= bits
        key |= np.uint32(n)
        for s in range(min(n, keep)):
            lo_ = np.minimum(slots[s], key)
            np.maximum(slots[s], key, out=key)
            slots[s] = lo_
        if n < keep:
            slots.append(key)
    column = np.arange(cell.size, dtype=np.intp).reshape(cell.shape)
    idx = np.empty((keep,) + cell.shape, np.int32)
    dist2 = np.empty(idx.shape, np.float32)
    for s in range(keep):
        n = (slots[s] & np.uint32((1 << viewgeom._KEY_BITS) - 1)).astype(np.intp)
        n[(slots[s] >> bits) >= viewgeom._KEY_MAX] = k
        n = n * cell.size + column
        idx[s] = lens.ravel().take(n)
        dist2[s] = dist.ravel().take(n)
    return idx, dist2


def opencv_view(plan, source, r, c, unit=1.0, support=None):
    """render_view as view_weights, slot_samples and cv2.accumulateProduct made it."""
    o = plan.layout.offset_image(r, c)
    ch = 1 if source.ndim == 2 else source.shape[2]
    H, W = plan.tile_weight.shape[1:]
    out = np.zeros((H, W) + ((ch,) if ch > 1 else ()), np.float32)
    w = view_weights(plan, r, c, with_gain=True, unit=unit, support=support)
    for k in range(w.shape[0]):
        s = slot_samples(plan, source, k, o)
        if source.dtype != np.float32:
            s = s.astype(np.float32)
        cv2.accumulateProduct(s.reshape(out.shape), w[k] if ch == 1 else cv2.merge([w[k]] * ch),
                              out)
    return out if ch > 1 else out[..., None]


def _turned_shot(turn: float):
    calib = RayCalib(**{**calib_for_optics(small_optics(480, 300)).__dict__,
                        "rotation": math.pi / 2 + turn})
    return patch6_shot(calib)


@pytest.mark.parametrize("turn", [0.0, 0.37])
def test_compiled_nearest_slots_are_the_numpy_sorting_networks_bits(turn):
    """The compiled pass gives the numpy chain's lenses and float32 distances bit for bit,
    for every count of slots and candidates the blends use and for bands at the top, in
    the middle and at the bottom of the view (pixels clipped into the table's margin)."""
    _, _, shot = _turned_shot(turn)
    layout = shot.layout
    H = layout.height
    for keep, k in ((1, 7), (3, 7), (4, 13), (7, 19)):
        for rows in (slice(0, 9), slice(H // 2 - 5, H // 2 + 6), slice(H - 7, H),
                     slice(None)):
            got = viewgeom._nearest_slots(layout, keep, k, rows)
            want = numpy_nearest_slots(layout, keep, k, rows)
            assert np.array_equal(got[0], want[0]), (keep, k, rows)
            assert np.array_equal(got[1].view(np.uint32), want[1].view(np.uint32))


def _frames(shape):
    rng = np.random.default_rng(5)
    base = cv2.GaussianBlur(rng.random(shape, np.float32), (0, 0), 1.2)
    base = (base - base.min()) / (base.max() - base.min())
    return {"uint8": (np.rint(base * 255).astype(np.uint8), 1 / 255),
            "uint16": (np.rint(base * 65535).astype(np.uint16) & np.uint16(0xFFF0), 1 / 65520),
            "float32": (base, 1.0)}


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("kind", ["uint8", "uint16", "float32"])
def test_compiled_view_is_the_opencv_chains_bits(kind, channels):
    """render_view (the compiled weights and maps, OpenCV's remap, the compiled blend)
    gives view_weights + slot_samples + cv2.accumulateProduct's float32 view bit for bit,
    and the same supports: 8- and 16-bit and float frames, grey and colour, the three
    blends (3, 4 and 7 slots), a profile per lens type (each slot's gain from its lens's
    row) and focus weights, central, edge and corner views, whole views and a band."""
    _, grid, shot = _turned_shot(0.37)
    layout = shot.layout
    frame, unit = _frames((300, 480, channels) if channels > 1 else (300, 480))[kind]
    lens_type = (np.arange(len(grid.centres)) % 3).astype(np.int64)[layout.lens_index]
    half = shot.safe.diameter_px / 2
    radii = np.arange(0.0, half + 1.5, BIN_PX)
    profiles = np.stack([np.clip(1.0 - a * (radii / half) ** 2, 0.4, 1.0)
                         for a in (0.5, 0.2, 0.0)]).astype(np.float32)
    focus = np.linspace(0.2, 1.0, len(layout.lens_index))
    blends = shot._blends
    for rows in (slice(None), slice(7, 29)):
        for plans in (make_plans(layout, shot.used_patch, shot.safe.diameter_px, blends,
                                 rows=rows),
                      make_plans(layout, shot.used_patch, shot.safe.diameter_px, blends,
                                 focus=focus, profile=profiles, profile_row=lens_type,
                                 rows=rows)):
            assert [p.lens.shape[0] for p in plans] == [b.slots for b in blends]
            for plan in plans:
                for r, c in ((2, 2), (0, 2), (0, 0), (4, 3)):
                    s_got = np.empty(plan.tile_weight.shape[1:], np.float32)
                    s_want = np.empty_like(s_got)
                    got = render_view(plan, frame, r, c, unit, support=s_got)
                    want = opencv_view(plan, frame, r, c, unit, support=s_want)
                    assert got.shape == want.shape
                    assert np.array_equal(got.view(np.uint32), want.view(np.uint32)), (
                        kind, rows, r, c, np.abs(got - want).max())
                    assert np.array_equal(s_got, s_want)


def test_render_view_refuses_a_frame_it_cannot_sample():
    _, _, shot = _turned_shot(0.0)
    with pytest.raises(ValueError, match="float64"):
        render_view(shot.plan, np.zeros((300, 480, 3)), 2, 2)
