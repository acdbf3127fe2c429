"""Depth maps for view synthesis: semi-global matching (SGM, Hirschmueller 2008) over
the multi-view plane-sweep cost volume, with occlusion handling, a multi-view
consistency check, background-side hole filling and an edge-aware weighted median.

What DERS / IVDE obtain with graph cuts, this obtains with SGM's path aggregation:

1. Matching cost per depth label (uniform in inverse depth between ``near`` and
   ``far``), per source: the truncated colour + gradient difference of the source
   warped onto the reference by the plane homography (:mod:`plenocal.depth.planesweep`),
   box-aggregated over a small window. Occlusions: per pixel and label the mean of
   the best ``ceil(S * best_fraction)`` sources that see it (a pixel occluded in
   some sources is still matched in the others).
2. SGM: along ``directions`` (4 or 8) scanline directions
   ``L_r(p, d) = C(p, d) + min(L_r(p-r, d), L_r(p-r, d+-1) + P1,
   min_k L_r(p-r, k) + P2(p)) - min_k L_r(p-r, k)``, summed over the directions.
   ``P2`` is lowered where the reference image has an edge between ``p-r`` and ``p``
   (depth edges follow image edges).
3. Winner-take-all with parabolic sub-label refinement.
4. Validity: the uniqueness ratio, and the consistency of the reference's depth with
   the depth the same SGM finds for the nearest source (left-right check,
   occlusions and mismatches fail it); small speckles are removed.
5. Hole filling from the background side: an invalid pixel takes the farther of the
   nearest valid depths to its left and right (holes are mostly disocclusions, seen
   by the reference but hidden behind a foreground edge in the sources), then the
   few left over by push-pull.
6. Edge-aware refinement: a weighted median of depth over a window with weights from
   the reference image's colour similarity (a joint-bilateral weighted median), which
   snaps depth edges to image edges and removes the fill's streaks.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numba
import numpy as np

from plenocal.camera import PinholeCamera
from plenocal.config import settings_from, stage_defaults, with_defaults
from plenocal.depth.costkernels import mean_of_seen_best
from plenocal.depth.planesweep import (
    PlaneSweepOptions,
    _grey,
    _remove_speckles,
    check_sweep_inputs,
    choose_num_depths,
    consistency_partner,
    depth_labels,
    left_right_check,
    source_costs,
)
from plenocal.io.files import to_float

log = logging.getLogger(__name__)

MIN_CONSISTENT = 0.01  # below this share of consistent pixels the check is not applied
LABEL_BLOCK = 16  # cost planes moved into the (H, W, D) volume at once (16 floats: 64 bytes)
_SGM = stage_defaults("depth.sgm")


@dataclass(frozen=True)
class SgmOptions:
    """SGM's settings; defaults: ``depth.sgm`` of config.schema.yaml."""
    num_depths: int | None = _SGM["num_depths"]  # None: from the sources' disparity range
    labels_per_px: float = _SGM["labels_per_px"]  # auto label count per px of disparity range
    min_depths: int = _SGM["min_depths"]
    max_depths: int = _SGM["max_depths"]
    window: int = _SGM["window"]  # matching window (odd) of the per-source cost
    best_fraction: float = _SGM["best_fraction"]  # share of the sources seeing a pixel averaged
    p1: float = _SGM["p1"]  # penalty of a one-label change between neighbours (cost, 0..1)
    p2: float = _SGM["p2"]  # penalty of a larger change, lowered at image edges
    edge_contrast: float = _SGM["edge_contrast"]  # grey difference (0..1) that halves P2
    directions: int = _SGM["directions"]  # 4 or 8 scanline directions
    uniqueness: float = _SGM["uniqueness"]  # best/second-best aggregated cost above: ambiguous
    consistency: bool = _SGM["consistency"]  # check against the nearest source's SGM depth
    consistency_tolerance: float = _SGM["consistency_tolerance"]  # relative agreement of it
    speckle_size: int = _SGM["speckle_size"]  # connected regions below this many px removed
    speckle_labels: float = _SGM["speckle_labels"]  # label jump that separates regions
    fill: bool = _SGM["fill"]  # background-side hole filling (dense output)
    median_radius: int = _SGM["median_radius"]  # weighted-median window radius (0 = off)
    median_sigma: float = _SGM["median_sigma"]  # colour difference (0..1) of its weights


def sgm_options(cfg: dict | None) -> SgmOptions:
    """SgmOptions from the config's ``depth.sgm`` block, partial or whole (missing keys: the
    schema's defaults; unknown keys ignored)."""
    return settings_from(SgmOptions, with_defaults("depth.sgm", cfg))


def _sweep_options(opt: SgmOptions) -> PlaneSweepOptions:
    return PlaneSweepOptions(num_depths=opt.num_depths, labels_per_px=opt.labels_per_px,
                             min_depths=opt.min_depths, max_depths=opt.max_depths,
                             cost="tad", window=opt.window, best_fraction=opt.best_fraction)


def matching_cost(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
                  src_imgs: list[np.ndarray], depths: np.ndarray,
                  opt: SgmOptions, out: np.ndarray | None = None) -> np.ndarray:
    """Cost volume (H, W, D) float32 in [0, 1]: per label the mean of the best
    ``ceil(S' * best_fraction)`` of the S' sources that see the pixel; 1 where none
    (written into ``out`` when given)."""
    S = len(srcs)
    # k per pixel from the number of sources that see it, by table
    k_of = np.maximum(1, np.ceil(np.arange(S + 1) * opt.best_fraction)).astype(np.int64)
    k_max = int(k_of[-1])
    D = len(depths)
    vol = _volume(out, (ref.height, ref.width, D))
    # labels in blocks of LABEL_BLOCK planes, each block moved into the label axis at once
    # (a (D, H, W) volume and its transposed copy cost 100 MB more and a slow strided pass)
    block = np.empty((min(LABEL_BLOCK, D), ref.height, ref.width), np.float32)
    for i, per in enumerate(source_costs(ref, ref_img, srcs, src_imgs, depths,
                                         _sweep_options(opt), cover="warped")):
        b = i % LABEL_BLOCK
        mean_of_seen_best(per, k_of, k_max, block[b])
        if b == len(block) - 1 or i == D - 1:
            _to_label_axis(block[:b + 1], vol, i - b)
    return vol


@numba.njit(cache=True)
def _to_label_axis(block, vol, first):  # pragma: no cover - numba
    """``vol[:, :, first:first + B] = block.transpose(1, 2, 0)`` for a (B, H, W) block."""
    B, H, W = block.shape
    for y in range(H):
        for x in range(W):
            o = vol[y, x]
            for b in range(B):
                o[first + b] = block[b, y, x]


@numba.njit(cache=True)
def _path_start(c, step):  # pragma: no cover - numba
    """A path's first pixel: its path costs are its matching costs ``c``, copied into
    ``step``; returns their minimum."""
    D = c.shape[0]
    for d in range(D):
        step[d] = c[d]
    m = step[0]
    for d in range(1, D):
        m = min(m, step[d])
    return m


@numba.njit(cache=True)
def _path_step(lp, lmin, pp2, p1, c, d):  # pragma: no cover - numba
    """L_r(p, d) of one label from the previous pixel's path costs ``lp`` (any d)."""
    D = lp.shape[0]
    best = lp[d]
    if d > 0 and lp[d - 1] + p1 < best:
        best = lp[d - 1] + p1
    if d < D - 1 and lp[d + 1] + p1 < best:
        best = lp[d + 1] + p1
    if lmin + pp2 < best:
        best = lmin + pp2
    return c[d] + best - lmin


@numba.njit(cache=True)
def _path_pixel(c, lp, lmin, pp2, p1, step):  # pragma: no cover - numba
    """``step[d] = L_r(p, d)`` for every label from the previous pixel's path costs ``lp``
    (their minimum ``lmin``) and the pixel's P2 ``pp2``; returns min_d L_r(p, d). The
    inner label loop has no branches (the end labels are done apart), so that it
    vectorises; the arithmetic (float64 from the penalty on, rounded to float32 per
    label) is the plain recursion's."""
    D = c.shape[0]
    jump = lmin + pp2
    step[0] = _path_step(lp, lmin, pp2, p1, c, 0)
    for d in range(1, D - 1):
        near = min(lp[d], min(lp[d - 1] + p1, lp[d + 1] + p1))
        step[d] = c[d] + min(np.float64(near), jump) - lmin
    if D > 1:
        step[D - 1] = _path_step(lp, lmin, pp2, p1, c, D - 1)
    m = step[0]
    for d in range(1, D):
        m = min(m, step[d])
    return m


@numba.njit(cache=True)
def _edge_p2(grey, y, x, py, px, p1, p2, contrast):  # pragma: no cover - numba
    """P2 between pixel (y, x) and the previous one on the path (py, px), lowered by the
    grey difference (edges), not below P1."""
    g = abs(grey[y, x] - grey[py, px])
    pp2 = p2 / (1.0 + g / contrast)
    if pp2 < p1:
        pp2 = p1
    return pp2


@numba.njit(cache=True)
def _aggregate_dir(cost, grey, dy, dx, p1, p2, contrast, out):  # pragma: no cover - numba
    """One direction's path costs added into ``out``."""
    H, W, D = cost.shape
    prev = np.zeros((W, D), np.float32)
    cur = np.zeros((W, D), np.float32)
    prev_min = np.zeros(W, np.float32)
    cur_min = np.zeros(W, np.float32)
    ys = range(H) if dy >= 0 else range(H - 1, -1, -1)
    for y in ys:
        xs = range(W) if dx >= 0 else range(W - 1, -1, -1)
        for x in xs:
            py, px = y - dy, x - dx
            c = cost[y, x]
            row = cur[x]  # written in place: the previous pixel is another row or column
            if py < 0 or py >= H or px < 0 or px >= W:
                m = _path_start(c, row)
            else:
                if dy == 0:
                    lp = cur[px]
                    lmin = cur_min[px]
                else:
                    lp = prev[px]
                    lmin = prev_min[px]
                pp2 = _edge_p2(grey, y, x, py, px, p1, p2, contrast)
                m = _path_pixel(c, lp, lmin, pp2, p1, row)
            cur_min[x] = m
            o = out[y, x]
            for d in range(D):
                o[d] += row[d]
        tmp = prev
        prev = cur
        cur = tmp
        tmp_m = prev_min
        prev_min = cur_min
        cur_min = tmp_m


@numba.njit(cache=True)
def _aggregate_rows(cost, grey, p1, p2, contrast, out):  # pragma: no cover - numba
    """The two horizontal directions, (0, 1) then (0, -1), row by row, written into
    ``out`` as ``L_(0,1) + L_(0,-1)`` - the bits of adding them in turn onto zeros (no
    path cost is -0) with one pass over the volumes instead of a zero fill and two."""
    H, W, D = cost.shape
    fwd = np.empty((W, D), np.float32)
    fwd_min = np.empty(W, np.float32)
    prev = np.empty(D, np.float32)  # the backward path's previous pixel and this one,
    step = np.empty(D, np.float32)  # swapped after each pixel instead of copied
    for y in range(H):
        fwd_min[0] = _path_start(cost[y, 0], fwd[0])
        for x in range(1, W):
            pp2 = _edge_p2(grey, y, x, y, x - 1, p1, p2, contrast)
            fwd_min[x] = _path_pixel(cost[y, x], fwd[x - 1], fwd_min[x - 1], pp2, p1, fwd[x])
        lmin = np.float32(0.0)
        for x in range(W - 1, -1, -1):
            c = cost[y, x]
            if x == W - 1:
                m = _path_start(c, step)
            else:
                pp2 = _edge_p2(grey, y, x, y, x + 1, p1, p2, contrast)
                m = _path_pixel(c, prev, lmin, pp2, p1, step)
            lmin = m
            o = out[y, x]
            f = fwd[x]
            for d in range(D):
                o[d] = f[d] + step[d]
            prev, step = step, prev


def sgm_aggregate(cost: np.ndarray, grey: np.ndarray, opt: SgmOptions,
                  out: np.ndarray | None = None) -> np.ndarray:
    """Sum over the scanline directions of the SGM path costs (H, W, D) (written into
    ``out`` when given)."""
    if opt.directions not in (4, 8):
        raise ValueError(f"depth.sgm.directions = {opt.directions}: must be 4 or 8")
    dirs = [(0, 1), (0, -1), (1, 0), (-1, 0)]
    if opt.directions == 8:
        dirs += [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    out = _volume(out, cost.shape)
    c = np.ascontiguousarray(cost, dtype=np.float32)
    g = np.ascontiguousarray(grey, dtype=np.float32)
    pen = (np.float32(opt.p1), np.float32(opt.p2), np.float32(opt.edge_contrast))
    _aggregate_rows(c, g, *pen, out)  # dirs[0] and dirs[1], the horizontal pair, at once
    for dy, dx in dirs[2:]:
        _aggregate_dir(c, g, dy, dx, *pen, out)
    return out


@numba.njit(cache=True)
def _wta_kernel(agg, near, far, depth, cont, ratio):  # pragma: no cover - numba
    """Per pixel in one pass: the first minimum over the labels, its parabolic sub-label
    offset (float32, as numpy computes it), the depth (uniform in inverse depth) and
    the best / second-best ratio with the second best taken outside +-1 label."""
    H, W, D = agg.shape
    f2 = np.float32(2.0)
    half = np.float32(0.5)
    eps = np.float32(1e-9)
    for y in range(H):
        for x in range(W):
            a = agg[y, x]
            best = 0
            c0 = a[0]
            for d in range(1, D):
                if a[d] < c0:
                    c0 = a[d]
                    best = d
            off = np.float32(0.0)
            if 1 <= best <= D - 2:
                cm = a[best - 1]
                cc = a[best]
                cp = a[best + 1]
                denom = cm - f2 * cc + cp
                if denom > eps:
                    off = half * (cm - cp) / denom
                    off = min(max(off, -half), half)
            c = best + np.float64(off)
            cont[y, x] = c
            depth[y, x] = np.float32(1.0 / (1.0 / near + c * (1.0 / far - 1.0 / near) / (D - 1)))
            second = np.float32(np.inf)
            for d in range(D):
                if (d < best - 1 or d > best + 1) and a[d] < second:
                    second = a[d]
            ratio[y, x] = c0 / second if second > 0 else np.float32(1.0)


def _wta(agg: np.ndarray, near: float, far: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(depth, continuous label, uniqueness ratio) from the aggregated volume (H, W, D)."""
    H, W, _ = agg.shape
    depth = np.empty((H, W), np.float32)
    cont = np.empty((H, W), np.float64)
    ratio = np.empty((H, W), np.float32)
    _wta_kernel(np.ascontiguousarray(agg, dtype=np.float32), float(near), float(far), depth,
                cont, ratio)
    return depth, cont, ratio


def _volume(buf: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """``buf`` when it is a float32 C-contiguous volume of ``shape``, else a new one."""
    if (buf is not None and buf.shape == tuple(shape) and buf.dtype == np.float32
            and buf.flags.c_contiguous):
        return buf
    return np.empty(shape, np.float32)


def _raw_sgm(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
             src_imgs: list[np.ndarray], near: float, far: float, n: int,
             opt: SgmOptions, work: tuple[np.ndarray, np.ndarray] | None = None,
             ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """SGM depth (0 where not unique or a speckle), its continuous label map and the
    two (H, W, n) volumes it used (cost, aggregate), which ``work`` passes to the next
    call: two volumes of some 100 MB each are not allocated and page-faulted again."""
    depths = depth_labels(near, far, n)
    cost_buf, agg_buf = work if work is not None else (None, None)
    cost = matching_cost(ref, ref_img, srcs, src_imgs, depths, opt, cost_buf)
    grey = _grey(ref_img)
    agg = sgm_aggregate(cost, grey, opt, agg_buf)
    depth, cont, ratio = _wta(agg, near, far)
    valid = (ratio <= opt.uniqueness) & np.isfinite(depth) & (depth > 0)
    valid = _remove_speckles(cont, valid, opt.speckle_size, opt.speckle_labels)
    return np.where(valid, depth, 0.0).astype(np.float32), cont, (cost, agg)


@numba.njit(cache=True)
def _fill_rows(depth):  # pragma: no cover - numba
    H, W = depth.shape
    out = depth.copy()
    for y in range(H):
        left = np.zeros(W, np.float32)
        last = np.float32(0.0)
        for x in range(W):
            if depth[y, x] > 0:
                last = depth[y, x]
            left[x] = last
        last = np.float32(0.0)
        for x in range(W - 1, -1, -1):
            if depth[y, x] > 0:
                last = depth[y, x]
            elif last > 0 or left[x] > 0:
                out[y, x] = max(last, left[x])  # the farther side: background
    return out


def fill_background(depth: np.ndarray) -> np.ndarray:
    """Invalid pixels (0) take the farther of the nearest valid depths left and right
    on their row; rows without any valid pixel are filled by push-pull of inverse depth
    over the whole map."""
    out = _fill_rows(np.ascontiguousarray(depth, dtype=np.float32))
    if (out <= 0).any() and (out > 0).any():
        from plenocal.verify.dibr import densify_depth  # noqa: PLC0415

        out, _ = densify_depth(out)
    return out.astype(np.float32)


@numba.njit(cache=True)
def _weighted_median(depth, guide, radius, inv2s2):  # pragma: no cover - numba
    H, W = depth.shape
    C = guide.shape[2]
    n = (2 * radius + 1) ** 2
    out = depth.copy()
    vals = np.empty(n, np.float32)
    wts = np.empty(n, np.float32)
    for y in range(H):
        for x in range(W):
            k = 0
            for yy in range(max(0, y - radius), min(H, y + radius + 1)):
                for xx in range(max(0, x - radius), min(W, x + radius + 1)):
                    z = depth[yy, xx]
                    if z <= 0:
                        continue
                    d2 = 0.0
                    for c in range(C):
                        t = guide[y, x, c] - guide[yy, xx, c]
                        d2 += t * t
                    vals[k] = z
                    wts[k] = np.exp(-d2 * inv2s2)
                    k += 1
            if k == 0:
                continue
            order = np.argsort(vals[:k])
            total = 0.0
            for i in range(k):
                total += wts[i]
            acc = 0.0
            for i in range(k):
                j = order[i]
                acc += wts[j]
                if acc >= 0.5 * total:
                    out[y, x] = vals[j]
                    break
    return out


def weighted_median(depth: np.ndarray, image: np.ndarray, radius: int,
                    sigma: float) -> np.ndarray:
    """Joint-bilateral weighted median of the valid depths in a (2 radius + 1)^2
    window, weights ``exp(-|I(p) - I(q)|^2 / (2 sigma^2))`` from the reference image."""
    if radius <= 0:
        return depth
    g = to_float(np.asarray(image))
    if g.ndim == 2:
        g = g[..., None]
    return _weighted_median(np.ascontiguousarray(depth, dtype=np.float32),
                            np.ascontiguousarray(g, dtype=np.float32), int(radius),
                            float(1.0 / (2.0 * sigma * sigma)))


def sgm_depth(ref: PinholeCamera, ref_img: np.ndarray, srcs: list[PinholeCamera],
              src_imgs: list[np.ndarray], near: float, far: float,
              opt: SgmOptions | None = None) -> np.ndarray:
    """Dense float32 z-depth map of the reference (cameras' units) for view synthesis
    (0 only where ``fill`` is off and the pixel is unreliable)."""
    opt = opt or SgmOptions()
    ref_img = check_sweep_inputs(ref, ref_img, srcs, near, far, "SGM depth")
    n = choose_num_depths(ref, srcs, near, far, _sweep_options(opt))
    depth, _, work = _raw_sgm(ref, ref_img, srcs, src_imgs, near, far, n, opt)
    if opt.consistency:
        j, others, other_imgs = consistency_partner(ref, ref_img, srcs, src_imgs)
        src_depth, _, _ = _raw_sgm(srcs[j], src_imgs[j], others, other_imgs, near, far, n,
                                   opt, work)
        ok = left_right_check(ref, depth, srcs[j], src_depth, opt.consistency_tolerance)
        ok = _remove_speckles(_inv_labels(depth, near, far, n), ok, opt.speckle_size,
                              opt.speckle_labels)
        if ok.mean() >= MIN_CONSISTENT or not opt.fill:
            depth = np.where(ok, depth, 0.0).astype(np.float32)
        else:  # the two views disagree everywhere (e.g. a wrong pose): keep SGM's own
            log.warning("SGM depth: only %.2f %% of the pixels pass the consistency check "
                        "with the nearest source; kept unchecked", 100 * ok.mean())
    if not (depth > 0).any():
        return depth.astype(np.float32)
    if opt.fill:
        depth = fill_background(depth)
    depth = weighted_median(depth, ref_img, opt.median_radius, opt.median_sigma)
    return depth.astype(np.float32)


def _inv_labels(depth: np.ndarray, near: float, far: float, n: int) -> np.ndarray:
    inv = 1.0 / np.maximum(depth, 1e-12)
    return (inv - 1.0 / near) / ((1.0 / far - 1.0 / near) / (n - 1))

