"""Compiled (numba) RGB -> YUV 4:2:0 of an integer view: :func:`plenocal.io.yuv.rgb_to_yuv`
of ``view x unit`` in one pass over the view's 2 x 2 blocks, the same bits (float32, the
same operations in the same order, no fast-math). The numpy version made a float copy of
the view and a dozen passes over it: 30 ms of each of Boxer's 2046 x 1126 views, 0.75 s
of a 25-view YUV conversion's 5.5 s. (Kept in a file of its own: numba's cache tracks a
kernel's own file only.)
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(inline="always")
def _code(v, offset, span, top):  # pragma: no cover - numba
    """``clip(rint(v span + offset), 0, top)`` (float32)."""
    return min(max(np.rint(v * span + offset), np.float32(0.0)), top)


@numba.njit(cache=True, nogil=True)
def view_to_yuv420(view, unit, kr, kg, kb, cb_scale, cr_scale, black, yspan, zero, cspan,
                   top, y_plane, cb_plane, cr_plane):  # pragma: no cover - numba
    """Fill ``y_plane`` (H, W) and the chroma planes (H // 2, W // 2) of the same integer
    type from ``view`` (H, W, 3) integers: each sample ``min(max(v unit, 0), 1)``; ``Y =
    kr R + kg G + kb B``, ``Cb = (B - Y) cb_scale``, ``Cr = (R - Y) cr_scale``; chroma the
    mean of each 2 x 2 block (``0.25 (c00 + c10 + c01 + c11)``, an odd last row or column
    left out); codes ``clip(rint(v span + offset), 0, top)``. Every number float32."""
    H, W = y_plane.shape
    h2, w2 = cb_plane.shape
    zero_f = np.float32(0.0)
    one = np.float32(1.0)
    quarter = np.float32(0.25)
    cb_row = np.empty((2, W), np.float32)
    cr_row = np.empty((2, W), np.float32)
    for y in range(H):
        j = y & 1
        for x in range(W):
            r = min(max(np.float32(view[y, x, 0]) * unit, zero_f), one)
            g = min(max(np.float32(view[y, x, 1]) * unit, zero_f), one)
            b = min(max(np.float32(view[y, x, 2]) * unit, zero_f), one)
            luma = kr * r + kg * g + kb * b
            y_plane[y, x] = _code(luma, black, yspan, top)
            cb_row[j, x] = (b - luma) * cb_scale
            cr_row[j, x] = (r - luma) * cr_scale
        if j == 1 and y // 2 < h2:
            i = y // 2
            for x2 in range(w2):
                a = 2 * x2
                cb = quarter * (((cb_row[0, a] + cb_row[1, a]) + cb_row[0, a + 1])
                                + cb_row[1, a + 1])
                cr = quarter * (((cr_row[0, a] + cr_row[1, a]) + cr_row[0, a + 1])
                                + cr_row[1, a + 1])
                cb_plane[i, x2] = _code(cb, zero, cspan, top)
                cr_plane[i, x2] = _code(cr, zero, cspan, top)
