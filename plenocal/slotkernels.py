"""Compiled (numba) core of :func:`plenocal.viewgeom.nearest_slots`: for every output pixel
of a band, the ``keep`` nearest of its ``k`` candidate lenses.

One pass over the pixels replaces the numpy chain of :func:`plenocal.viewgeom._nearest_slots`
(per candidate: a lookup, a squared distance, a key and ``keep`` min / max passes over
whole arrays, then a gather per slot): 1.6 of HandTools' 18 thread-seconds went there.
It gives the same bits: the pixel's cell from the same float64 operations, the squared
distance in the same float32 operations and order, the same uint32 keys ``quantised d2 <<
5 | candidate`` and so the same order (ties keep the candidate order). No fast-math.
(Kept in a file of its own: numba's cache tracks a kernel's own file only.)
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def nearest_slots_band(table, shape1, lo0, lo1, binv, ref, ys, width, steps, tcx, tcy,
                       inv_t2, key_scale, key_max, key_bits, idx, dist2
                       ):  # pragma: no cover - numba
    """Fill ``idx`` (keep, h, W) int32 and ``dist2`` (keep, h, W) float32 for the output
    rows ``ys`` (h,) float64 of a view ``width`` wide.

    ``table``: the flat lens table of the tile lattice (-1: none), ``shape1`` its second
    side, ``(lo0, lo1)`` its first cell's lattice coordinates; ``binv`` (2, 2) float64
    the output-pixel -> lattice matrix about the tile centre ``ref`` (2,) float64;
    ``steps`` (k, 2) int64 the candidates' lattice steps; ``tcx``, ``tcy`` (m + 1,)
    float32 the tile centres with ``inf`` appended (index -1: no lens); ``inv_t2``
    float32 ``1 / T^2``; the key's scale (float32), clamp (uint32) and bits."""
    keep = idx.shape[0]
    k = steps.shape[0]
    n0 = table.shape[0] // shape1
    lens = np.empty(k + 1, np.int32)
    dist = np.empty(k + 1, np.float32)
    keys = np.empty(keep, np.uint32)
    lens[k] = -1
    dist[k] = np.inf
    fmax = np.float32(key_max)
    mask = np.uint32((1 << key_bits) - 1)
    bits = np.uint32(key_bits)
    m = tcx.shape[0] - 1
    for yi in range(ys.shape[0]):
        y = ys[yi]
        yf = np.float32(y)
        dy0 = y - ref[1]
        for x in range(width):
            dx0 = np.float64(x) - ref[0]
            ax = np.rint(binv[0, 0] * dx0 + binv[0, 1] * dy0) - lo0
            ay = np.rint(binv[1, 0] * dx0 + binv[1, 1] * dy0) - lo1
            cx = np.int64(min(max(ax, 2.0), n0 - 3.0))
            cy = np.int64(min(max(ay, 2.0), shape1 - 3.0))
            xf = np.float32(x)
            filled = 0
            for n in range(k):
                li = table[(cx + steps[n, 0]) * shape1 + cy + steps[n, 1]]
                lens[n] = li
                j = li if li >= 0 else m
                ddx = xf - tcx[j]
                ddy = yf - tcy[j]
                d = (ddx * ddx + ddy * ddy) * inv_t2
                dist[n] = d
                q = min(d * key_scale, fmax)
                key = min(np.uint32(q), np.uint32(key_max))
                key = (key << bits) | np.uint32(n)
                # insert: the slots filled so far stay sorted
                s = 0
                while s < filled:
                    if keys[s] > key:
                        keys[s], key = key, keys[s]
                    s += 1
                if filled < keep:
                    keys[filled] = key
                    filled += 1
            for s in range(keep):
                key = keys[s]
                n = np.int64(key & mask)
                if (key >> bits) >= np.uint32(key_max):
                    n = k
                idx[s, yi, x] = lens[n]
                dist2[s, yi, x] = dist[n]
