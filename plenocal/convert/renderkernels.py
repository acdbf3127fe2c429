"""Compiled (numba) parts of :func:`plenocal.convert.render.render_view`, the same bits as
the numpy and OpenCV chain they replaced.

That chain made, per view and slot, the samples' offsets and radial table entries, their
weights and OpenCV's fixed-point maps (``cv2.convertMaps``) in passes over whole arrays,
then a ``cv2.remap``, a float copy and a product (``cv2.accumulateProduct``): 2.7 of
HandTools' 3.6 s of views on one core. OpenCV's remap stays (its vector code reads a
slot's samples in 3 ns a pixel, faster than anything compiled here); around it:

- :func:`slot_weights_and_maps`, per band row and slot: the runs of pixels that share a
  lens (a tile's width: the lens's values read once), then the table lookups, then the
  fixed-point maps, each in a loop of its own (loops of arithmetic alone vectorise): the
  weights as :func:`plenocal.convert.render.view_weights` makes them (float32, the same
  operations in the same order) and the positions as ``cv2.convertMaps`` rounds them, to
  1/32 px (``rint(32 x)``: an integer part and a 5-bit fraction);
- :func:`accumulate_slots`, the blend as ``cv2.accumulateProduct`` adds it: ``acc + s w``
  in float64 (the product of two float32 is exact there), rounded to float32. OpenCV
  fuses the multiply and add and rounds once. The float64 sum is exact where ``acc`` and
  ``s w`` are within a factor of 2^6 of each other; elsewhere it rounds first, and the
  second rounding then differs from the single one only where the first lands on a
  float32 half-way point: about one such sum in 2^29 (none on the tests' frames or the
  real ones: ``tests/test_renderkernels.py``, BENCHMARKS.md).

No fast-math: the same bits on every run and with any number of threads. (Kept in a file
of its own: numba's cache tracks a kernel's own file only.)
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def slot_weights_and_maps(lens, tile_weight, floor_weight, y0, lens_scale, tcx, tcy, lcx,
                          lcy, lens_row, weight_table, gain_table, radial_scale, ox, oy,
                          unit, w, xy, frac, support):  # pragma: no cover - numba
    """For the band of output rows ``y0 ..``: each slot's normalised weight times its
    vignetting gain into ``w`` (K, h, W) float32, its sample's fixed-point position into
    ``xy`` (K, h, W, 2) int16 and ``frac`` (K, h, W) uint16 (``cv2.convertMaps``' CV_16SC2
    maps), and each pixel's support (:func:`plenocal.convert.render.pixel_support`) into
    ``support`` (h, W) float32.

    ``lens`` (K, h, W) int32 each slot's used lens (-1: none); ``tile_weight`` (K, h, W)
    and ``floor_weight`` (h, W) float32 (:class:`plenocal.convert.render.RenderPlan`);
    per used lens (m,): ``lens_scale`` float32 (``sign P / T``), its tile centre ``tcx,
    tcy`` and micro-image centre ``lcx, lcy`` float32, ``lens_row`` int64 its row of
    ``gain_table`` (T, L); ``weight_table`` (L,) float32 and ``radial_scale``
    (:func:`plenocal.convert.render.radial_tables`); ``(ox, oy)`` float32 the view's
    offset q_rc; ``unit`` float32 the source's unit. A slot without a lens weighs 0 and
    samples the frame's corner (OpenCV's maps put it far outside: the same 0 in the
    blend)."""
    K, h, W = lens.shape
    L = weight_table.shape[0]
    top = np.float32(L - 1)
    half = np.float32(0.5)
    tiny = np.float32(1e-12)
    sub = np.float32(32.0)
    total = np.empty(W, np.float32)
    g = np.empty((K, W), np.float32)
    ent = np.empty(W, np.int32)
    px = np.empty(W, np.float32)
    gbase = np.empty(W, np.int32)
    fyr = np.empty(W, np.int32)
    qyr = np.empty(W, np.int16)
    gains = gain_table.ravel()
    # per row and slot: each pixel's table entry, x position (1/32 px) and its lens's
    # gain row, y position and fraction (constant along a run), then the table lookups,
    # then the fixed-point maps: loops of arithmetic alone vectorise, lookups do not
    for yi in range(h):
        yf = np.float32(y0 + yi)
        for k in range(K):
            row = lens[k, yi]
            a = 0
            while a < W:  # runs of pixels whose slot k holds one lens
                li = row[a]
                e = a + 1
                while e < W and row[e] == li:
                    e += 1
                if li < 0:
                    for x in range(a, e):
                        ent[x] = 0
                        px[x] = 0.0
                        gbase[x] = 0
                        fyr[x] = 0
                        qyr[x] = 0
                    a = e
                    continue
                s = lens_scale[li]
                cx = tcx[li]
                mx = lcx[li]
                offy = (yf - tcy[li]) * s
                ey = offy + oy
                ey *= ey
                iy = np.int64(np.rint((offy + lcy[li] + oy) * sub))
                qy = np.int16(min(max(iy >> 5, -32768), 32767))
                fy = np.int32((iy & 31) * 32)
                gb = np.int32(lens_row[li] * L)
                for x in range(a, e):
                    offx = (np.float32(x) - cx) * s
                    ex = offx + ox
                    ex *= ex
                    ex += ey
                    ex *= radial_scale
                    ex += half
                    ent[x] = np.int32(min(ex, top))
                    px[x] = (offx + mx + ox) * sub
                    gbase[x] = gb
                    fyr[x] = fy
                    qyr[x] = qy
                a = e
            wk = w[k, yi]
            wt = tile_weight[k, yi]
            gk = g[k]
            for x in range(W):
                en = ent[x]
                wk[x] = weight_table[en] * wt[x]
                gk[x] = gains[gbase[x] + en]
            qk = xy[k, yi]
            fk = frac[k, yi]
            for x in range(W):
                ix = np.int32(np.rint(px[x]))
                qk[x, 0] = np.int16(min(max(ix >> 5, -32768), 32767))
                qk[x, 1] = qyr[x]
                fk[x] = np.uint16(fyr[x] + (ix & 31))
        # the pixels' totals and supports, and the normalisation (view_weights' order)
        for x in range(W):
            total[x] = 0.0
        for k in range(K):
            wk = w[k, yi]
            for x in range(W):
                total[x] += wk[x]
        for x in range(W):
            t = total[x]
            support[yi, x] = t - floor_weight[yi, x]
            total[x] = unit / max(t, tiny)
        for k in range(K):
            wk = w[k, yi]
            gk = g[k]
            for x in range(W):
                wk[x] = (wk[x] * total[x]) * gk[x]


@numba.njit(cache=True, nogil=True)
def accumulate_slots(samples, w, out):  # pragma: no cover - numba
    """``out`` (h, W, C) float32 += ``samples[k] w[k]`` for each slot k in turn, each sum
    rounded as ``cv2.accumulateProduct`` rounds it (the module docstring); ``samples``
    (K, h, W, C) of any type, ``w`` (K, h, W) float32, both C-contiguous. Row by row, each
    slot's weights spread over the channels first, so that the sum runs over one
    contiguous row (it vectorises: twice as fast as a loop over the channels of each
    pixel)."""
    K, h, W, C = samples.shape
    spread = np.empty(W * C, np.float64)
    for y in range(h):
        acc = out[y].reshape(W * C)
        for k in range(K):
            s = samples[k, y].reshape(W * C)
            wk = w[k, y]
            for x in range(W):
                v = np.float64(wk[x])
                for c in range(C):
                    spread[x * C + c] = v
            for i in range(W * C):
                acc[i] = np.float32(np.float64(acc[i]) + np.float64(s[i]) * spread[i])


def warm() -> None:
    """Load every compiled kernel of the views (:mod:`plenocal.slotkernels` and this
    module) with the argument types a conversion gives them (8- and 16-bit frames), on
    arrays of a few pixels: numba's first call loads its cache and sets itself up, about
    0.3 s (0.5 s with ``import numba``), which :func:`warm_in_background` hides behind
    the frame's decoding."""
    from plenocal.slotkernels import nearest_slots_band  # noqa: PLC0415

    f = np.float32
    idx = np.empty((1, 1, 1), np.int32)
    nearest_slots_band(np.full(64, -1, np.int32), 8, 0.0, 0.0, np.eye(2), np.zeros(2),
                       np.zeros(1), 1, np.zeros((1, 2), np.int64), np.zeros(2, f),
                       np.zeros(2, f), f(1.0), f(1.0), np.uint32(1), 5, idx,
                       np.empty((1, 1, 1), f))
    w = np.empty((1, 1, 1), f)
    per_lens = [np.zeros(1, f)] * 5
    slot_weights_and_maps(np.zeros((1, 1, 1), np.int32), np.zeros((1, 1, 1), f),
                          np.zeros((1, 1), f), 0, *per_lens, np.zeros(1, np.int64),
                          np.ones(2, f), np.ones((1, 2), f), f(1.0), f(0.0), f(0.0), f(1.0),
                          w, np.empty((1, 1, 1, 2), np.int16), np.empty((1, 1, 1), np.uint16),
                          np.empty((1, 1), f))
    for dtype in (np.uint8, np.uint16):
        accumulate_slots(np.zeros((1, 1, 1, 3), dtype), w, np.zeros((1, 1, 3), f))


def warm_in_background() -> None:
    """:func:`warm` on a daemon thread: the conversion goes on (reading the frame lets go
    of the GIL), and its first call of a kernel waits for numba's lock if the load is
    still under way. An error here is left to that first call to raise."""
    import threading  # noqa: PLC0415

    def run() -> None:
        try:
            warm()
        except Exception:  # noqa: BLE001, S110  (the real call raises it with its context)
            pass

    threading.Thread(target=run, name="plenocal-warm-kernels", daemon=True).start()
