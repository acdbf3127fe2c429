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

Memory: where most of a frame's lenses are filled (a frame that barely matches, or the
wrong MLA kind), most rows of every view hold weak pixels, and a window is the whole
view (77 MB in float32 for a 31-MP frame's view of 2930 x 2188). The finest level is
therefore made and blended in strips (:func:`push_pull_rows`), and the renderer keeps a
band's scattered weak pixels as a :class:`SparseConfidence`: a 31-MP frame converted with
the wrong kind peaked at 2.1 GB, and is under 1 GB (``bench/bench_memory.py``), with
the same bytes.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

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
#: rows of a view window blended at a time at the pyramid's finest level (the fill's
#: memory: a few MB a strip, whatever the window)
STRIP_ROWS = 128


def support_confidence(support: np.ndarray) -> np.ndarray:
    """``c = clip(support / SUPPORT_FULL, 0, 1)`` (float32, the shape of ``support``)."""
    c = np.multiply(support, np.float32(1.0 / SUPPORT_FULL), dtype=np.float32)
    return np.clip(c, 0.0, 1.0, out=c)


def push_pull(img: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(h, w, C) float32 estimate of ``img`` (h, w, C) float32 from its pixels weighted by
    ``c`` (h, w) in [0, 1]: ``c img + (1 - c) up(est_1)``, ``est_l`` the same one level
    down the pyramid (the module docstring), down to a level where every pixel has
    support or one row or column is left (there, pixels without support take the
    support-weighted mean of the whole level). No support at all: ``img`` unchanged.
    The whole of :func:`push_pull_rows`."""
    out = np.empty(img.shape, np.float32)
    for rows, est in push_pull_rows(img, c):
        out[rows] = est
    return out


def push_pull_rows(img: np.ndarray, c: np.ndarray) -> Iterator[tuple[slice, np.ndarray]]:
    """:func:`push_pull`'s estimate, :data:`STRIP_ROWS` rows at a time: yields
    ``(rows, (len(rows), w, C) float32)``, top to bottom, the same bits as the whole.
    ``img`` (h, w, C) of any dtype, read as float32 strip by strip: no level-0 array of
    the image's size is made (a whole view of a 31-MP frame's filled lenses is 77 MB in
    float32), and ``img``'s rows may be overwritten once their strip is yielded (the
    coarser levels are made before the first). The levels are made strip by strip with
    the context OpenCV's 5-tap kernels reach (:func:`_down_rows`, :func:`_up_rows`)."""
    h, w = c.shape
    if float(c.max()) <= 0.0:
        for r0 in range(0, h, STRIP_ROWS):
            yield slice(r0, min(r0 + STRIP_ROWS, h)), img[r0:r0 + STRIP_ROWS].astype(np.float32)
        return
    if min(h, w) <= 1:  # one row or column: no pyramid, the level's mean where c is 0
        num = img.astype(np.float32) * c[..., None]
        mean = num.sum(axis=(0, 1)) / max(float(c.sum()), 1e-30)
        est = num / np.maximum(c, np.float32(1e-12))[..., None]
        est[c <= 0] = mean
        yield slice(0, h), est
        return
    nums = [None, _down_rows(img, c)]
    dens = [c, cv2.pyrDown(c)]
    while min(dens[-1].shape) > 1 and float(dens[-1].min()) < LEVEL_SUPPORT:
        nums.append(_down(nums[-1]))
        dens.append(cv2.pyrDown(dens[-1]))
    d = dens[-1]
    mean = nums[-1].sum(axis=(0, 1)) / max(float(d.sum()), 1e-30)
    est = nums[-1] / np.maximum(d, np.float32(1e-12))[..., None]
    est[d <= 0] = mean
    for lv in range(len(nums) - 2, 0, -1):  # ``a v + (1 - a) up``, in place (the same bits)
        lh, lw = dens[lv].shape
        up = _up(est, (lw, lh))
        a = np.minimum(dens[lv] * np.float32(1.0 / LEVEL_SUPPORT), np.float32(1.0))[..., None]
        est, v = None, nums[lv]
        nums[lv] = None
        np.divide(v, np.maximum(dens[lv], np.float32(1e-12))[..., None], out=v)
        np.multiply(a, v, out=v)
        np.multiply(1.0 - a, up, out=up)
        est = np.add(v, up, out=v)
    del nums, dens
    for r0 in range(0, h, STRIP_ROWS):
        rows = slice(r0, min(r0 + STRIP_ROWS, h))
        a = c[rows, :, None]
        yield rows, a * img[rows].astype(np.float32) + (1.0 - a) * _up_rows(est, rows, h, w)


def _down_rows(img: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``cv2.pyrDown(img * c)`` (img read as float32) made from strips of
    :data:`STRIP_ROWS` input rows with 4 rows of context each side: the same bits as the
    whole, without the whole product."""
    h, w = c.shape
    out = np.empty(((h + 1) // 2, (w + 1) // 2, img.shape[2]), np.float32)
    half = STRIP_ROWS // 2
    for r0 in range(0, out.shape[0], half):
        r1 = min(r0 + half, out.shape[0])
        i0, i1 = max(0, 2 * r0 - 4), min(h, 2 * r1 + 4)  # i0 even: row r is i0 // 2 + k
        part = img[i0:i1].astype(np.float32) * c[i0:i1, :, None]
        out[r0:r1] = _down(part)[r0 - i0 // 2:r1 - i0 // 2]
    return out


def _up_rows(est: np.ndarray, rows: slice, h: int, w: int) -> np.ndarray:
    """Rows ``rows`` of ``cv2.pyrUp(est, dstsize=(w, h))``, made from ``est``'s rows that
    reach them (2 of context each side): the same bits as the whole."""
    j0 = max(0, rows.start // 2 - 2)
    j1 = min(est.shape[0], (rows.stop + 1) // 2 + 2)
    dh = h - 2 * j0 if j1 == est.shape[0] else 2 * (j1 - j0)  # the last rows: h's parity
    return _up(est[j0:j1], (w, dh))[rows.start - 2 * j0:rows.stop - 2 * j0]


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


@dataclass(frozen=True)
class SparseConfidence:
    """A block's confidence (:func:`support_confidence`) that is 1 but at ``idx`` (flat
    indices into ``shape``, int32), where it is ``vals`` (float32, each below 1): 8 bytes
    a weak pixel, against the dense block's 4 a pixel."""
    shape: tuple[int, int]
    idx: np.ndarray
    vals: np.ndarray

    def low_rows(self) -> np.ndarray:
        """The rows that hold a pixel below 1, ascending."""
        return np.unique(self.idx // self.shape[1])

    def low_columns(self, rows: slice) -> np.ndarray:
        """The columns that hold a pixel below 1 within ``rows``, ascending."""
        y = self.idx // self.shape[1]
        return np.unique(self.idx[(y >= rows.start) & (y < rows.stop)] % self.shape[1])

    def paste(self, out: np.ndarray, rows: slice, cols: slice) -> None:
        """Write the block's ``[rows, cols]`` into ``out`` (of that shape, holding 1)."""
        y, x = np.divmod(self.idx, self.shape[1])
        k = (y >= rows.start) & (y < rows.stop) & (x >= cols.start) & (x < cols.stop)
        out[y[k] - rows.start, x[k] - cols.start] = self.vals[k]


#: a block's confidence as stored by :func:`weak_box`: dense, or its pixels below 1
Confidence = np.ndarray | SparseConfidence


def weak_box(support: np.ndarray) -> tuple[int, int, Confidence] | None:
    """The confidence (:func:`support_confidence`) of ``support`` (h, W) over the box of
    its pixels below 1, as ``(first row, first column, confidence)``; None where every
    pixel has full support. The renderer keeps only these boxes, band by band: as the
    (h', w') block, or as a :class:`SparseConfidence` where under half of the block is
    below 1 (on a frame whose lenses are mostly filled, most bands' boxes span the view
    with a tenth of their pixels weak)."""
    if float(support.min()) >= SUPPORT_FULL:
        return None
    ys, xs = box_of(support < np.float32(SUPPORT_FULL))
    c = support_confidence(support[ys, xs])
    low = np.flatnonzero(c < 1.0)
    if 2 * len(low) >= c.size:
        return ys.start, xs.start, c
    return ys.start, xs.start, SparseConfidence(c.shape, low.astype(np.int32), c.flat[low])


def _low_rows(c: Confidence) -> np.ndarray:
    """The rows of block ``c`` that hold a pixel below 1, ascending."""
    if isinstance(c, SparseConfidence):
        return c.low_rows()
    return np.flatnonzero((c < 1.0).any(axis=1))


def _low_columns(c: Confidence, rows: slice) -> np.ndarray:
    """The columns of block ``c`` that hold a pixel below 1 within ``rows``, ascending."""
    if isinstance(c, SparseConfidence):
        return c.low_columns(rows)
    return np.flatnonzero((c[rows] < 1.0).any(axis=0))


def fill_unsupported(view: np.ndarray,
                     confidence: np.ndarray | list[tuple[int, int, Confidence]]) -> np.ndarray:
    """``view`` (H, W, C; uint8, uint16 or float32) with each pixel whose confidence
    (:func:`support_confidence`) is below 1 taken in proportion ``1 - c`` from its
    supported neighbours (:func:`push_pull`); in place, and returned. Rounded for
    integers. ``confidence``: (H, W), or boxes that hold every pixel below 1 as
    ``[(first row, first column, (h, w) or sparse confidence)]`` (1 elsewhere;
    :func:`weak_box`).
    The fill works on windows: runs of rows that need it, then runs of columns within
    those rows, each with :data:`SLAB_MARGIN_PX` of context."""
    H, W = view.shape[:2]
    boxes = [(0, 0, confidence)] if isinstance(confidence, np.ndarray) else confidence
    low_rows = [y0 + _low_rows(c) for y0, _, c in boxes]
    rows = np.unique(np.concatenate(low_rows)) if low_rows else np.zeros(0, np.intp)
    if not len(rows):
        return view

    def window(a: int, b: int, a2: int, b2: int) -> np.ndarray:
        out = np.ones((b - a, b2 - a2), np.float32)
        for y0, x0, c in boxes:
            lo, hi = max(a, y0), min(b, y0 + c.shape[0])
            lo2, hi2 = max(a2, x0), min(b2, x0 + c.shape[1])
            if lo < hi and lo2 < hi2:
                rows, cols = slice(lo - y0, hi - y0), slice(lo2 - x0, hi2 - x0)
                part = out[lo - a:hi - a, lo2 - a2:hi2 - a2]
                if isinstance(c, SparseConfidence):
                    c.paste(part, rows, cols)
                else:
                    part[...] = c[rows, cols]
        return out

    for a, b, y0, y1 in _runs(rows, H):
        need = np.zeros(W, bool)  # the columns with a pixel below 1 in rows y0:y1
        for by, bx, c in boxes:
            lo, hi = max(y0, by), min(y1, by + c.shape[0])
            if lo < hi:
                need[bx + _low_columns(c, slice(lo - by, hi - by))] = True
        for a2, b2, x0, x1 in _runs(np.flatnonzero(need), W):
            conf = window(a, b, a2, b2)
            # strip by strip: each strip's rows are written once made (push_pull_rows)
            for strip, est in push_pull_rows(view[a:b, a2:b2], conf):
                lo, hi = max(strip.start, y0 - a), min(strip.stop, y1 - a)
                if lo >= hi:
                    continue
                part = est[lo - strip.start:hi - strip.start, x0 - a2:x1 - a2]
                if view.dtype != np.float32:
                    np.rint(part, out=part)
                    np.clip(part, 0, np.iinfo(view.dtype).max, out=part)
                mask = conf[lo:hi, x0 - a2:x1 - a2] < 1.0
                view[a + lo:a + hi, x0:x1][mask] = part[mask].astype(view.dtype)
    return view
