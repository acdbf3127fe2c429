"""Pixels of a view that no micro image sees from inside its rim, and their fill.

The blend (:mod:`plenocal.convert.render`) weighs every sample by how far it lies from
its micro-image centre, down to a tiny floor past the rim. Where every lens that covers
an output pixel samples past its rim, the floor's samples decide the pixel: they carry
the neighbouring micro images' light, and along a view's edge (the lens that would see
the point nearer its centre is off the sensor) they show as a row of notches, triangles
up to a quarter of a tile deep (HandTools' top views, Origami's; a few pixels of the
simulator's corner views); inside the views of the wide blend (the corner views,
:func:`plenocal.convert.render.rim_reach`), where the in-rim weight is small, they draw
faint outlines of the tiles.
A pixel's support (:func:`plenocal.convert.render.pixel_support`) is the weight of its
in-rim samples; one with less than :data:`SUPPORT_FULL` is taken, in proportion, from its
supported neighbours::

    out = c view + (1 - c) fill,     c = min(support / SUPPORT_FULL, 1)

``fill`` is a normalised push-pull over a Gaussian pyramid of ``c view`` and ``c``: at
each level the support-weighted mean where that level's neighbourhood has support, the
coarser level's estimate where it has not, so a hole is filled from the nearest supported
pixels whatever its size. (:func:`plenocal.verify.dibr.push_pull` fills the DIBR's holes
the same way but with binary weights; here a partly supported pixel adds to the fill in
proportion to its support. The two could share one pyramid; merging them changes the
filled values, so it waits for a re-measure over captures.) Only pixels with ``c < 1``
change; they are processed in
windows around them (:data:`SLAB_MARGIN_PX` of context each side), fixed by the
confidence alone.
"""

from __future__ import annotations

import cv2
import numpy as np

#: support (in-rim blend weight; a sample at its micro-image centre with a whole tile
#: weight has 1) from which a pixel is its blend's alone. From 0.01 on, the floor's past-rim
#: samples (0.001 times each lens's tile weight) make at most a quarter of a pixel of a
#: 3-lens blend.
SUPPORT_FULL = 0.01
#: rows (columns) of context each side of the rows (columns) that need a fill
SLAB_MARGIN_PX = 16
#: a level's support share from which its own mean stands (below it, the coarser one's
#: estimate is mixed in)
LEVEL_SUPPORT = 0.25


def support_confidence(support: np.ndarray) -> np.ndarray:
    """``c = clip(support / SUPPORT_FULL, 0, 1)`` (float32, the shape of ``support``)."""
    c = np.multiply(support, np.float32(1.0 / SUPPORT_FULL), dtype=np.float32)
    return np.clip(c, 0.0, 1.0, out=c)


def push_pull(img: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(h, w, C) float32 estimate of ``img`` (h, w, C) float32 from its pixels weighted by
    ``c`` (h, w) in [0, 1]: ``c img + (1 - c) up(est_1)``, ``est_l`` the same one level
    down the pyramid (the module docstring), down to a level where every pixel has
    support or one row or column is left (there, pixels without support take the
    support-weighted mean of the whole level). No support at all: ``img`` unchanged."""
    if float(c.max()) <= 0.0:
        return img.copy()
    nums = [img * c[..., None]]
    dens = [c]
    while min(dens[-1].shape) > 1 and (len(dens) == 1 or float(dens[-1].min()) < LEVEL_SUPPORT):
        nums.append(_down(nums[-1]))
        dens.append(cv2.pyrDown(dens[-1]))
    d = dens[-1]
    mean = nums[-1].sum(axis=(0, 1)) / max(float(d.sum()), 1e-30)
    est = nums[-1] / np.maximum(d, np.float32(1e-12))[..., None]
    est[d <= 0] = mean
    for lv in range(len(nums) - 2, -1, -1):
        h, w = dens[lv].shape
        up = _up(est, (w, h))
        if lv == 0:
            a = c
            v = img
        else:
            a = np.minimum(dens[lv] * np.float32(1.0 / LEVEL_SUPPORT), np.float32(1.0))
            v = nums[lv] / np.maximum(dens[lv], np.float32(1e-12))[..., None]
        est = a[..., None] * v + (1.0 - a[..., None]) * up
    return est


def _down(x: np.ndarray) -> np.ndarray:
    """cv2.pyrDown keeping the channel axis (h, w, C)."""
    y = cv2.pyrDown(x)
    return y.reshape(y.shape[0], y.shape[1], x.shape[2])


def _up(x: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """cv2.pyrUp to ``size`` (w, h) keeping the channel axis."""
    y = cv2.pyrUp(x, dstsize=size)
    return y.reshape(size[1], size[0], x.shape[2])


def _runs(idx: np.ndarray, size: int) -> list[tuple[int, int, int, int]]:
    """(a, b, y0, y1): windows a:b holding the indices y0:y1 that need a fill, for runs of
    ``idx`` (sorted) closer than two margins merged, within ``range(size)``."""
    out: list[tuple[int, int]] = []
    y0 = y1 = int(idx[0])
    for y in idx[1:]:
        if y - y1 > 2 * SLAB_MARGIN_PX:
            out.append((y0, y1 + 1))
            y0 = int(y)
        y1 = int(y)
    out.append((y0, y1 + 1))
    return [(max(a - SLAB_MARGIN_PX, 0), min(b + SLAB_MARGIN_PX, size), a, b) for a, b in out]


def box_of(mask: np.ndarray) -> tuple[slice, slice] | None:
    """The rows and columns spanning the true pixels of ``mask`` (h, w); None where none
    is true."""
    rows = np.flatnonzero(mask.any(axis=1))
    if not len(rows):
        return None
    cols = np.flatnonzero(mask[rows[0]:rows[-1] + 1].any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def weak_box(support: np.ndarray) -> tuple[int, int, np.ndarray] | None:
    """The confidence (:func:`support_confidence`) of ``support`` (h, W) over the box of
    its pixels below 1, as ``(first row, first column, (h', w') confidence)``; None where
    every pixel has full support. The renderer keeps only these boxes, band by band."""
    if float(support.min()) >= SUPPORT_FULL:
        return None
    ys, xs = box_of(support < np.float32(SUPPORT_FULL))
    return ys.start, xs.start, support_confidence(support[ys, xs])


def fill_unsupported(view: np.ndarray,
                     confidence: np.ndarray | list[tuple[int, int, np.ndarray]]) -> np.ndarray:
    """``view`` (H, W, C; uint8, uint16 or float32) with each pixel whose confidence
    (:func:`support_confidence`) is below 1 taken in proportion ``1 - c`` from its
    supported neighbours (:func:`push_pull`); in place, and returned. Rounded for
    integers. ``confidence``: (H, W), or boxes that hold every pixel below 1 as
    ``[(first row, first column, (h, w) confidence)]`` (1 elsewhere; :func:`weak_box`).
    The fill works on windows: runs of rows that need it, then runs of columns within
    those rows, each with :data:`SLAB_MARGIN_PX` of context."""
    H, W = view.shape[:2]
    boxes = [(0, 0, confidence)] if isinstance(confidence, np.ndarray) else confidence
    low_rows = [y0 + np.flatnonzero((c < 1.0).any(axis=1)) for y0, _, c in boxes]
    rows = np.unique(np.concatenate(low_rows)) if low_rows else np.zeros(0, np.intp)
    if not len(rows):
        return view

    def window(a: int, b: int, a2: int, b2: int) -> np.ndarray:
        out = np.ones((b - a, b2 - a2), np.float32)
        for y0, x0, c in boxes:
            lo, hi = max(a, y0), min(b, y0 + c.shape[0])
            lo2, hi2 = max(a2, x0), min(b2, x0 + c.shape[1])
            if lo < hi and lo2 < hi2:
                out[lo - a:hi - a, lo2 - a2:hi2 - a2] = c[lo - y0:hi - y0, lo2 - x0:hi2 - x0]
        return out

    for a, b, y0, y1 in _runs(rows, H):
        cols = np.flatnonzero((window(y0, y1, 0, W) < 1.0).any(axis=0))
        for a2, b2, x0, x1 in _runs(cols, W):
            conf = window(a, b, a2, b2)
            est = push_pull(view[a:b, a2:b2].astype(np.float32), conf)
            part = est[y0 - a:y1 - a, x0 - a2:x1 - a2]
            if view.dtype != np.float32:
                np.rint(part, out=part)
                np.clip(part, 0, np.iinfo(view.dtype).max, out=part)
            mask = conf[y0 - a:y1 - a, x0 - a2:x1 - a2] < 1.0
            view[y0:y1, x0:x1][mask] = part[mask].astype(view.dtype)
    return view
