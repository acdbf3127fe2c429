"""Compiled (numba) pieces of the plane sweep's inner loop (:mod:`plenocal.depth.planesweep`,
shared with SGM): the per-pixel truncated colour + gradient difference, the mask of the
windows a warped source does not cover (from the homography), the mean of the best-k
source costs (of all sources: the plane sweep; of those that see the pixel: SGM) and the
winner-take-all over the labels. (Kept in one file: numba's cache tracks a kernel's own
file only, so a kernel here calls no compiled function of another module.)

Each but the mask replaces a chain of whole-image numpy passes (and their temporaries) by
one pass and gives the same bits: the same float32 operations in the same order, no
fast-math.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _tad_row(r, s, o, diff):  # pragma: no cover - numba
    """One row of :func:`tad_pixels`: ``r`` and ``s`` interleaved (4 W), ``o`` (W)."""
    c08 = np.float32(0.08)
    c04 = np.float32(0.04)
    c3 = np.float32(0.3)
    c7 = np.float32(0.7)
    for i in range(diff.shape[0]):
        diff[i] = abs(r[i] - s[i])
    for x in range(o.shape[0]):
        a = min(diff[4 * x], c08) / c08
        b = min(diff[4 * x + 1] + diff[4 * x + 2], c04) / c04
        o[x] = a * c3 + b * c7


@numba.njit(cache=True)
def tad_pixels(ref_feat, warped, dc):  # pragma: no cover - numba
    """Per pixel ``0.3 min(|dI|, 0.08) / 0.08 + 0.7 min(|dIx| + |dIy|, 0.04) / 0.04``
    (float32, in numpy's order of operations) into ``dc``.

    ``ref_feat`` and ``warped`` are (H, W, 4) float32 and C-contiguous: grey, x and y
    gradients and a fourth channel that is not read (a four-channel warp costs what a
    one-channel warp costs and vectorises). Row by row: the absolute differences of the
    whole interleaved row first (one contiguous pass that vectorises), then the
    per-pixel terms."""
    H, W = dc.shape
    diff = np.empty(4 * W, np.float32)
    rf = ref_feat.reshape(H, 4 * W)
    wf = warped.reshape(H, 4 * W)
    for y in range(H):
        _tad_row(rf[y], wf[y], dc[y], diff)


@numba.njit(cache=True)
def tad_pixels_cover(ref_feat, warped, dc, cover):  # pragma: no cover - numba
    """:func:`tad_pixels`, and the warped coverage channel (the fourth) copied into the
    (H, W) plane ``cover`` while its row is in cache: SGM's coverage test box-filters it,
    and numpy's strided copy of the channel was a pass of its own (a tenth of a source's
    cost per label, issue 15)."""
    H, W = dc.shape
    diff = np.empty(4 * W, np.float32)
    rf = ref_feat.reshape(H, 4 * W)
    wf = warped.reshape(H, 4 * W)
    for y in range(H):
        s = wf[y]
        _tad_row(rf[y], s, dc[y], diff)
        c = cover[y]
        for x in range(W):
            c[x] = s[4 * x + 3]


#: the validity threshold of the box-filtered coverage channel (a window mean at or
#: below it leaves the source image; :func:`mask_box_uncovered`)
COVERED = np.float32(0.999)


@numba.njit(cache=True)
def mask_box_uncovered(box_cover, cost):  # pragma: no cover - numba
    """+inf into ``cost`` where ``box_cover`` (the box-filtered warped coverage channel) is
    at or below :data:`COVERED`: the window leaves the source image. One pass instead of
    numpy's comparison and masked copy."""
    H, W = cost.shape
    thr = COVERED
    inf = np.float32(np.inf)
    for y in range(H):
        b = box_cover[y]
        o = cost[y]
        for x in range(W):
            if b[x] <= thr:
                o[x] = inf


@numba.njit(cache=True)
def _inside_columns(hom, src_w, src_h, y):  # pragma: no cover - numba
    """The columns ``[lo, hi]`` (real numbers; lo > hi: none) of reference row ``y`` whose
    sampling position ``hom @ (x, y, 1)`` (reference -> source, as warped with
    ``cv2.WARP_INVERSE_MAP``) lies in front of the source and inside its pixel centres
    ``[0, src_w - 1] x [0, src_h - 1]``. Along a row the position is a projective map of
    x, so with ``w = h20 x + d > 0`` each bound is a linear inequality ``a x + b >= 0``."""
    b0 = hom[0, 1] * y + hom[0, 2]
    b1 = hom[1, 1] * y + hom[1, 2]
    d = hom[2, 1] * y + hom[2, 2]
    lo = -np.inf
    hi = np.inf
    for k in range(5):
        if k == 0:  # u >= 0
            a, b = hom[0, 0], b0
        elif k == 1:  # u <= src_w - 1
            a, b = (src_w - 1.0) * hom[2, 0] - hom[0, 0], (src_w - 1.0) * d - b0
        elif k == 2:  # v >= 0
            a, b = hom[1, 0], b1
        elif k == 3:  # v <= src_h - 1
            a, b = (src_h - 1.0) * hom[2, 0] - hom[1, 0], (src_h - 1.0) * d - b1
        else:  # in front: w > 0
            a, b = hom[2, 0], d - 1e-12
        if a > 0.0:
            lo = max(lo, -b / a)
        elif a < 0.0:
            hi = min(hi, -b / a)
        elif b < 0.0:
            return np.inf, -np.inf
    return lo, hi


@numba.njit(cache=True)
def mask_uncovered(hom, src_w, src_h, half, cost):  # pragma: no cover - numba
    """+inf into ``cost`` (H, W) where the matching window (``2 half + 1`` square, mirrored
    at the reference's borders as the box filter mirrors it) samples the source outside
    its image: some pixel of the window maps, by the reference -> source homography
    ``hom``, outside ``[0, src_w - 1] x [0, src_h - 1]`` or behind the source.

    A homography maps the window's rectangle to a convex quadrilateral, so the window is
    inside when its rows' inside intervals (:func:`_inside_columns`) all hold its
    columns: per row one interval, per pixel two comparisons. (Until issue 15 the mask was
    a box filter of a warped coverage channel, <= 0.999: the same windows, but for
    positions within a fiftieth of a pixel of the border, at a fifth of a source cost's
    time.)"""
    H, W = cost.shape
    lo = np.empty(H)
    hi = np.empty(H)
    for y in range(H):
        lo[y], hi[y] = _inside_columns(hom, src_w, src_h, y)
    inf = np.float32(np.inf)
    for y in range(H):
        wlo = -np.inf
        whi = np.inf
        for r in range(max(y - half, 0), min(y + half, H - 1) + 1):
            wlo = max(wlo, lo[r])
            whi = min(whi, hi[r])
        o = cost[y]
        for x in range(W):
            if not (wlo <= max(x - half, 0) and min(x + half, W - 1) <= whi):
                o[x] = inf


@numba.njit(cache=True, fastmath={"nnan", "nsz"})
def _bubble_smallest(per, y, passes, run):  # pragma: no cover - numba
    """``passes`` bubble passes over row ``y`` of the planes of ``per`` (S, H, W): after
    pass i plane i holds the i-th smallest value (the first ``passes`` ascending, the
    rest a permutation of the others). Each pass carries the running minimum from the
    last plane down in the row buffer ``run``: per plane one load and one store (the
    values of exchanging neighbouring planes pairwise, from the last to plane i, by
    element-wise min/max).
    Costs are never NaN nor -0 (the fastmath flags that let min/max vectorise)."""
    S = per.shape[0]
    W = per.shape[2]
    for i in range(passes):
        last = per[S - 1, y]
        for x in range(W):
            run[x] = last[x]
        for j in range(S - 1, i, -1):
            p = per[j - 1, y]
            q = per[j, y]
            for x in range(W):
                a = p[x]
                m = run[x]
                q[x] = max(a, m)
                run[x] = min(a, m)
        first = per[i, y]
        for x in range(W):
            first[x] = run[x]


@numba.njit(cache=True)
def mean_of_best(per, k, out):  # pragma: no cover - numba
    """Per pixel of ``per`` (S, H, W, overwritten): the mean of its ``k`` smallest costs,
    summed in ascending order in float32 (+inf when one of them is), divided by ``k``
    in float32. With ``k == S`` the sum keeps the sources' order (nothing is sorted)."""
    S, H, W = per.shape
    run = np.empty(W, np.float32)
    kf = np.float32(k)
    for y in range(H):
        if k < S:
            _bubble_smallest(per, y, min(k, S - 1), run)
        o = out[y]
        first = per[0, y]
        for x in range(W):
            o[x] = first[x]
        for m in range(1, k):
            p = per[m, y]
            for x in range(W):
                o[x] += p[x]
        for x in range(W):
            o[x] /= kf


@numba.njit(cache=True, fastmath={"nnan", "nsz"})
def mean_of_seen_best(per, k_of, k_max, out):  # pragma: no cover - numba
    """Per pixel of ``per`` (S, H, W, overwritten): the mean of the ``k_of[S']`` smallest
    of the S' finite costs (summed in ascending order, float32), 1 where no source sees
    it. Row by row, ``k_max`` bubble passes (unseen +inf last; each pass carries the
    running minimum down in a row buffer: one load and one store per plane), then the sum
    plane by plane, masked by each pixel's k. The costs are never NaN nor -0 (the
    fastmath flags that let the min/max vectorise), and the sums keep their order (no
    reassociation)."""
    S, H, W = per.shape
    seen = np.empty(W, np.int32)
    k = np.empty(W, np.int32)
    run = np.empty(W, np.float32)
    for y in range(H):
        seen[:] = 0
        for s in range(S):
            row = per[s, y]
            for x in range(W):
                seen[x] += np.int32(row[x] < np.inf)
        _bubble_smallest(per, y, min(k_max, S - 1), run)
        o = out[y]
        first = per[0, y]
        for x in range(W):
            k[x] = k_of[seen[x]]
            o[x] = first[x]
        for m in range(1, k_max):
            p = per[m, y]
            for x in range(W):
                if m < k[x]:
                    o[x] += p[x]
        for x in range(W):
            o[x] = o[x] / np.float32(k[x]) if seen[x] > 0 else np.float32(1.0)


@numba.njit(cache=True)
def wta_labels(vol, inv0, step, best, depth, c0, second):  # pragma: no cover - numba
    """Per pixel of the cost volume ``vol`` (D, H, W; non-finite costs read as 1e6): the
    first minimum over the labels ``best`` and its cost ``c0``, the parabolic sub-label
    offset and the depth ``1 / (inv0 + (best + offset) step)``, and the second-best cost
    outside +-1 label - with numpy's float32 / float64 arithmetic of
    :func:`plenocal.depth.planesweep.winner_take_all`. Row by row over the labels (each
    label row contiguous)."""
    D, H, W = vol.shape
    big = np.float32(1e6)
    two = np.float32(2.0)
    half = np.float32(0.5)
    eps = np.float32(1e-9)
    inf = np.float32(np.inf)
    for y in range(H):
        b = best[y]
        c = c0[y]
        s = second[y]
        row = vol[0, y]
        for x in range(W):
            v = row[x]
            c[x] = v if abs(v) < inf else big
            b[x] = 0
        for d in range(1, D):
            row = vol[d, y]
            for x in range(W):
                v = row[x]
                v = v if abs(v) < inf else big
                if v < c[x]:
                    c[x] = v
                    b[x] = d
        for x in range(W):
            s[x] = big
        for d in range(D):
            row = vol[d, y]
            for x in range(W):
                v = row[x]
                v = v if abs(v) < inf else big
                bx = b[x]
                lo = max(bx - 1, 0)
                hi = min(bx + 1, D - 1)
                if (d < lo or d > hi) and v < s[x]:
                    s[x] = v
        z = depth[y]
        for x in range(W):
            bx = b[x]
            i = min(max(bx, 1), D - 2)
            cm = vol[i - 1, y, x]
            cc = vol[i, y, x]
            cp = vol[i + 1, y, x]
            cm = cm if abs(cm) < inf else big
            cc = cc if abs(cc) < inf else big
            cp = cp if abs(cp) < inf else big
            off = np.float32(0.0)
            if 1 <= bx <= D - 2:
                denom = (cm - two * cc) + cp
                if denom > eps:
                    off = (half * (cm - cp)) / denom
                    off = min(max(off, -half), half)
            inv_d = inv0 + (np.float64(bx) + np.float64(off)) * step
            z[x] = np.float32(1.0 / inv_d)
