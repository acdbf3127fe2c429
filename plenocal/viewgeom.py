"""Which sensor point each output pixel of subaperture view (r, c) samples.

This is the one piece of geometry shared by the converter (it renders with it),
the ground truth (it traces the chief rays it selects) and registration B's exact
model (which follows from it). It depends on the grid and the convert settings
only, never on image content: the per-lens patch size enters as an argument.

Layout. Every lens whose whole micro image lies on the sensor and is not cut by the main
lens (:mod:`plenocal.convert.bordercut`) ("used" lens) owns a tile of ``T x T`` output
pixels (the tile size) centred at::

    o_i = (m_i - c_s) * T / D + ((W_v - 1) / 2, (H_v - 1) / 2)

``m_i`` the micro-image centre, ``c_s`` the sensor centre, both in IMAGE axes (x right,
y down): the output is the sensor image scaled by ``T / D`` about its centre, so the
views stand as the scene stands in the raw frame whatever the grid's rotation (0,
pi/2 or a small angle). The optical axis lands on the centre of every view's tile
grid, which is what registration A assumes (principal point at the image centre) for
the central view. ``W_v`` and ``H_v`` are chosen symmetric about the axis so that every
output pixel lies inside the span of used lens centres: odd, ``2 floor(half) + 1``,
or with ``even`` one pixel less, ``2 floor(half)``, for YUV 4:2:0 tools; either way
the axis lies on the image centre ``((W_v - 1) / 2, (H_v - 1) / 2)`` (between two
pixels for even sizes), where registration A puts the principal point.

Sampling. View (r, c) of an N x N set has the offset
``q_rc = ((c - (N-1)/2) q, (r - (N-1)/2) q)`` (pixels, image axes) from the
micro-image centre, with ``q = D' sin(45 deg) / N`` by default (the paper). Output
pixel ``u`` in the tile of lens ``i`` whose patch size is ``P_i`` samples::

    m_i + q_rc - (u - o_i) * P_i / T     (Keplerian MLA: every micro image inverted)
    m_i + q_rc + (u - o_i) * P_i / T     (Galilean MLA: micro images upright)

The tile centre ``u = o_i`` samples ``m_i + q_rc`` whatever ``P_i`` is: its chief ray
defines the view's pinhole.

Orientation of the view index. A sensor pixel at offset ``x`` from a micro-image
centre sees the scene along the straight line through the microlens centre, i.e.
from the opposite side of the main-lens pupil, for both MLA kinds; the raw frame is
read out so that the scene stands upright (image turned by the main lens and turned
back by the readout), which turns the pupil with it. So a step of ``+q`` along image
x in every micro image is a viewpoint step to the RIGHT, ``+q`` along y a step DOWN,
for Keplerian and Galilean MLAs alike: view (r, c) has r growing as the viewpoint
moves down and c as it moves right. Measured: on Fujita2 (a Raytrix frame, whose
micro images are upright: ``galilean``) the kangaroo moves left against the books
behind it from view (2, 0) to (2, 4) and up from (0, 2) to (4, 2)
(``tests/test_convert_real.py``); on Boys2 (TSPC, ``keplerian``) the boy's hair moves
4-14 px left / up while the backdrop moves 26 px right / down (by hand: the face is
too plain for a test); on the simulator (``keplerian``) the view cameras' centres
move right with c (``tests/test_groundtruth.py``).
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from plenocal.grid import MicrolensGrid
from plenocal.names import central_view, parse_view, view_name, view_names  # noqa: F401
from plenocal.optics import view_spacing


def view_position(r: int, c: int, n: int) -> tuple[int, int]:
    """(h, v): the view's step from the centre, horizontal and vertical (Eq. 4)."""
    h = (n - 1) // 2
    return c - h, r - h


MLA_KINDS = ("keplerian", "galilean")


def mla_sign(mla: str) -> float:
    """-1 for a Keplerian MLA (micro images inverted), +1 for a Galilean one."""
    if mla not in MLA_KINDS:
        raise ValueError(f"MLA kind must be one of {', '.join(MLA_KINDS)} (got {mla!r})")
    return -1.0 if mla == "keplerian" else 1.0


@dataclass(frozen=True)
class ViewLayout:
    n_views: int
    tile: int  # T, output pixels per lens pitch
    q: float  # view spacing in sensor pixels
    width: int  # output view size
    height: int
    lens_index: np.ndarray  # (m,) indices into the grid of the used lenses
    tile_centres: np.ndarray  # (m, 2) output pixel of each used lens's tile centre
    lens_centres: np.ndarray  # (m, 2) micro-image centres of the used lenses (sensor px)
    basis: np.ndarray  # (2, 2) rows: output-pixel steps of lattice steps (1, 0) and (0, 1)
    mla: str = "keplerian"  # micro images inverted (keplerian) or upright (galilean)

    @property
    def sign(self) -> float:
        """-1 (Keplerian) or +1 (Galilean): the sign of ``(u - o_i) P / T`` in sampling."""
        return mla_sign(self.mla)

    def offset(self, r: int, c: int) -> np.ndarray:
        """q_rc, image axes (pixels): +x for a viewpoint step right, +y down."""
        h, v = view_position(r, c, self.n_views)
        return np.array([h * self.q, v * self.q])

    def offset_image(self, r: int, c: int) -> np.ndarray:
        """q_rc as an image-space vector on the sensor (the layout is in image axes)."""
        return self.offset(r, c)

    def chief_sensor_points(self, r: int, c: int) -> np.ndarray:
        """Sensor points sampled by the tile centres of view (r, c): m_i + R q_rc."""
        return self.lens_centres + self.offset_image(r, c)

    def sensor_points(self, r: int, c: int, lens: np.ndarray, out_xy: np.ndarray,
                      patch: np.ndarray) -> np.ndarray:
        """Sensor positions sampled by output pixels ``out_xy`` (..., 2) of view (r, c)
        through used-lens indices ``lens`` (...) with patch sizes ``patch`` (...)."""
        d = (out_xy - self.tile_centres[lens]) * (patch / self.tile)[..., None]
        return self.lens_centres[lens] + self.offset(r, c) + self.sign * d


def make_layout(grid: MicrolensGrid, n_views: int, tile: int, q: float | None = None,
                margin: float = 0.0, mla: str = "keplerian", even: bool = False,
                insets_px: Mapping[str, float] | None = None) -> ViewLayout:
    """Build the output layout of the N x N views of one lenslet image (image axes; see
    the module docstring). ``even``: crop the last column / row where the size is odd.
    ``insets_px``: per sensor border, the distance under which lenses are left out (their
    micro images cut by the main lens: :mod:`plenocal.convert.bordercut`); the size stays
    symmetric about the axis, so the opposite border loses as many rows."""
    mla_sign(mla)
    if n_views < 1 or n_views % 2 == 0:
        raise ValueError(f"the number of views per side must be odd (got {n_views})")
    if tile < 1:
        raise ValueError(f"tile size must be >= 1 (got {tile})")
    if q is None:
        q = view_spacing(grid.calib.safe_diameter, n_views)
    used = np.flatnonzero(grid.inside(margin) & grid.lit(insets_px))
    if len(used) < 4:
        raise ValueError("fewer than 4 microlenses lie wholly on the sensor: does calib.xml "
                         "belong to this lenslet image?")
    D = grid.diameter
    sensor_centre = np.array([(grid.width - 1) / 2, (grid.height - 1) / 2])
    rel = (grid.centres[used] - sensor_centre) / D  # lens units, image axes
    lo, hi = rel.min(axis=0), rel.max(axis=0)
    half = np.minimum(-lo, hi) * tile
    if (half <= 1).any():
        raise ValueError("the sensor centre lies outside the microlens grid")
    size = 2 * np.floor(half).astype(int) + (0 if even else 1)
    width, height = int(size[0]), int(size[1])
    centre_out = np.array([(width - 1) / 2, (height - 1) / 2])
    tile_centres = rel * tile + centre_out
    return ViewLayout(
        n_views=n_views, tile=int(tile), q=float(q), width=width, height=height,
        lens_index=used, tile_centres=tile_centres, lens_centres=grid.centres[used],
        basis=grid.A.T / D * tile, mla=mla,
    )


#: lattice steps from a pixel's cell (its lattice coordinates rounded), ring by ring: the
#: cell's tile centre, its six neighbours (1 pitch), the next six (sqrt 3) and the six
#: after (2)
_STEPS = np.array([(0, 0), (1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1),
                   (1, 1), (-1, -1), (2, -1), (-2, 1), (1, -2), (-1, 2),
                   (2, 0), (0, 2), (-2, 2), (-2, 0), (0, -2), (2, -2)])
#: candidates (the first steps of _STEPS) that hold every lens within a radius (tile
#: units) of any pixel. A pixel's cell is its lattice coordinates rounded, a parallelogram
#: whose corners lie sqrt(3)/2 from its centre (not the hexagon of the nearest centre), so
#: the rings up to r hold every lens nearer than the next ring's distance less sqrt(3)/2
CANDIDATE_RINGS = ((7, math.sqrt(3.0) / 2), (13, 2.0 - math.sqrt(3.0) / 2),
                   (19, math.sqrt(7.0) - math.sqrt(3.0) / 2))


def candidates_within(radius: float) -> int:
    """How many candidates (:data:`_STEPS`) hold every lens within ``radius`` tiles of any
    output pixel (7 up to 0.87 tiles, 13 up to 1.13, 19 up to 1.78); ValueError beyond."""
    for count, reach in CANDIDATE_RINGS:
        if radius <= reach:
            return count
    raise ValueError(f"a blend radius of {radius} tiles needs lenses beyond the "
                     f"{CANDIDATE_RINGS[-1][0]} candidates (at most "
                     f"{CANDIDATE_RINGS[-1][1]:.2f} tiles)")


_MARGIN = 5  # empty lattice cells around the used lenses in the lookup table


def _rows(layout: ViewLayout, rows: slice, dtype) -> np.ndarray:
    """The output rows ``rows`` (a slice of ``range(layout.height)``) as a column."""
    return np.arange(layout.height, dtype=dtype)[rows][:, None]


def _lattice_table(layout: ViewLayout
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The lens table of the tile lattice with a margin of empty cells (-1), flattened;
    its shape (2,); the lattice coordinates of its first cell (2,); the output-pixel ->
    lattice matrix (2, 2) and the tile centre it is taken about (2,)."""
    c0 = layout.tile_centres
    ref = c0[0]
    B = layout.basis.T  # columns: output-pixel vectors of the two lattice steps
    Binv = np.linalg.inv(B)
    lat = np.rint((c0 - ref) @ Binv.T).astype(np.int64)
    lo = lat.min(axis=0) - _MARGIN
    shape = lat.max(axis=0) - lo + 1 + _MARGIN
    table = np.full(tuple(shape), -1, dtype=np.int32)
    table[lat[:, 0] - lo[0], lat[:, 1] - lo[1]] = np.arange(len(c0))
    return table.ravel(), shape, lo, Binv, ref


def _lattice_lookup(layout: ViewLayout, k: int, rows: slice = slice(None)
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lens table of the tile lattice, flattened with a margin of empty cells (-1),
    each output pixel's cell (its lattice coordinates rounded, a parallelogram, not the
    nearest lens's hexagon; (h, W) int32 into the flat table for the output ``rows``,
    kept ``_MARGIN - 3`` cells inside it) and the flat
    offsets of the first ``k`` lattice steps: the candidate lens of step n at pixel u is
    ``table[cell[u] + off[n]]``."""
    ys = _rows(layout, rows, np.float64)
    xs = np.arange(layout.width, dtype=np.float64)[None, :]
    table, shape, lo, Binv, ref = _lattice_table(layout)
    ax = np.rint(Binv[0, 0] * (xs - ref[0]) + Binv[0, 1] * (ys - ref[1]))
    ay = np.rint(Binv[1, 0] * (xs - ref[0]) + Binv[1, 1] * (ys - ref[1]))
    # a pixel clipped in lies >= 3 empty cells from every lens: its steps (<= 2) find none
    ax = np.clip(ax - lo[0], 2, shape[0] - 3).astype(np.int32)
    ay = np.clip(ay - lo[1], 2, shape[1] - 3).astype(np.int32)
    cell = ax * np.int32(shape[1]) + ay
    steps = _STEPS[: max(k, 1)]
    return table, cell, (steps[:, 0] * shape[1] + steps[:, 1]).astype(np.int32)


def _tile_dist2(layout: ViewLayout, li: np.ndarray, rows: slice = slice(None)
                ) -> np.ndarray:
    """Squared distance (tile units, float32) from each output pixel of ``rows`` to the
    tile centre of lens ``li`` (h, W); inf where ``li`` is -1."""
    f = np.float32
    ys = _rows(layout, rows, f)
    xs = np.arange(layout.width, dtype=f)[None, :]
    # index -1 (no lens): a centre at infinity, so that its distance is inf
    cx = np.append(layout.tile_centres[:, 0], np.inf).astype(f)
    cy = np.append(layout.tile_centres[:, 1], np.inf).astype(f)
    dx = xs - cx.take(li)
    dy = ys - cy.take(li)
    dx *= dx
    dy *= dy
    dx += dy
    dx *= f(1.0 / layout.tile ** 2)
    return dx


def _candidates(layout: ViewLayout, k: int, rows: slice = slice(None)):
    """Yield, for the first ``k`` lattice steps around each output pixel's (of ``rows``)
    cell's tile centre, (lens index (h, W) int32, -1 where none; squared distance to its
    tile centre in tile units (h, W) float32, inf where none)."""
    table, cell, off = _lattice_lookup(layout, k, rows)
    for o in off:
        li = table.take(cell + o)
        yield li, _tile_dist2(layout, li, rows)


def nearest_lenses(layout: ViewLayout, k: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """For every output pixel, up to ``k`` used lenses whose tiles may cover it.

    Returns (lens index into the layout (H, W, k), -1 where none; squared distance to
    the tile centre in tile units (H, W, k)). Candidates are the first ``k`` steps of
    :data:`_STEPS` from the pixel's cell: the default 7 (the cell's lens and its six
    neighbours) hold every lens within 0.87 tiles, not every lens within one
    (:func:`candidates_within`; the renderer's :func:`nearest_slots` takes as many as its
    blends need).
    """
    idx, dist2 = zip(*_candidates(layout, k), strict=True)
    return np.stack(idx, axis=-1).astype(np.int64), np.stack(dist2, axis=-1)


_KEY_SCALE = float(1 << 22)  # squared tile distances quantised to 2^-22 for the order
_KEY_MAX = (1 << 27) - 1  # quantised d2 clamped here: 32 tiles^2 or more away, or no lens
_KEY_BITS = 5  # the candidate's number in the key's low bits (up to 31 candidates)


#: the most bytes of tables :func:`remembered_slots` keeps: a 12-MP TSPC frame's views of
#: 1574 x 1190 px need 105 MB for their 7 slots; a 31-MP sensor's more than this, and
#: the bands past it are made each time, as without the block (the memory stays bounded)
SLOT_MEMO_BYTES = 128 << 20


class _SlotMemo:
    """:func:`nearest_slots`' tables by layout geometry and band, up to ``max_bytes``."""

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self.used = 0
        self.tables: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self.lock = threading.Lock()

    def put(self, key: tuple, tables: tuple[np.ndarray, np.ndarray]) -> None:
        size = sum(t.nbytes for t in tables)
        with self.lock:
            if key in self.tables or self.used + size > self.max_bytes:
                return
            for t in tables:
                t.flags.writeable = False  # handed out again: nobody may change them
            self.tables[key] = tables
            self.used += size


_slot_memo: _SlotMemo | None = None


@contextlib.contextmanager
def remembered_slots(max_bytes: int = SLOT_MEMO_BYTES) -> Iterator[None]:
    """Within the block :func:`nearest_slots` keeps the tables it makes (read-only, up to
    ``max_bytes``) and gives the same arrays when asked again for the same layout
    geometry, band and counts: they depend on the layout alone, and the frames of one
    recording share one layout (one set-up; :mod:`plenocal.convert.video`), so that
    every frame after the first skips them (0.36 s a frame of a 12-MP TSPC recording on
    one core). The numbers are those made without the block. Blocks do not nest."""
    global _slot_memo
    if _slot_memo is not None:
        raise RuntimeError("remembered_slots: a block is already open")
    _slot_memo = _SlotMemo(max_bytes)
    try:
        yield
    finally:
        _slot_memo = None


def slots_remembered() -> bool:
    """Whether a :func:`remembered_slots` block is open."""
    return _slot_memo is not None


def _slot_key(layout: ViewLayout, keep: int, k: int, rows: slice) -> tuple:
    """What :func:`nearest_slots`' tables depend on: the layout's size, tile, lattice
    basis and tile centres (a digest), the counts and the band's rows."""
    h = hashlib.blake2b(digest_size=16)
    for a in (layout.tile_centres, layout.basis):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return (layout.width, layout.height, layout.tile, h.hexdigest(), keep, k,
            rows.indices(layout.height))


def nearest_slots(layout: ViewLayout, keep: int = 3, k: int = 7, rows: slice = slice(None)
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The ``keep`` nearest of :func:`nearest_lenses`'s ``k`` candidates, nearest first,
    slot-major, for the output ``rows`` (all by default; a band gives the same numbers as
    those rows of the whole): (lens index (keep, h, W) int32, -1 where none; squared
    distance in tile units (keep, h, W) float32, inf where none). Ties (to 2^-22 tile^2)
    keep the candidate order: each pixel's uint32 keys ``quantised d2 << 5 | candidate``
    kept sorted by insertion, ``keep`` of them, in one compiled pass over the pixels
    (:mod:`plenocal.slotkernels`; the bits of the numpy sorting network it replaced).
    ``k``: up to ``len(_STEPS)`` (19) candidates (:func:`candidates_within`). Inside
    :func:`remembered_slots` the tables are made once per layout geometry and band and
    handed out again, read-only."""
    if k > len(_STEPS):
        raise ValueError(f"nearest_slots takes at most {len(_STEPS)} candidates, got {k}")
    keep = min(keep, k)
    memo = _slot_memo
    key = None if memo is None else _slot_key(layout, keep, k, rows)
    if memo is not None and key in memo.tables:
        return memo.tables[key]
    idx, dist2 = _nearest_slots(layout, keep, k, rows)
    if memo is not None:
        memo.put(key, (idx, dist2))
    return idx, dist2


def _nearest_slots(layout: ViewLayout, keep: int, k: int, rows: slice
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_slots` computed, in one compiled pass over the pixels
    (:func:`plenocal.slotkernels.nearest_slots_band`)."""
    from plenocal.slotkernels import nearest_slots_band  # noqa: PLC0415 (numba: 0.3 s)

    f = np.float32
    table, shape, lo, Binv, ref = _lattice_table(layout)
    ys = np.arange(layout.height, dtype=np.float64)[rows]
    idx = np.empty((keep, len(ys), layout.width), np.int32)
    dist2 = np.empty(idx.shape, np.float32)
    # index -1 (no lens): a centre at infinity, so that its distance is inf
    tcx = np.append(layout.tile_centres[:, 0], np.inf).astype(f)
    tcy = np.append(layout.tile_centres[:, 1], np.inf).astype(f)
    nearest_slots_band(table, int(shape[1]), float(lo[0]), float(lo[1]),
                       np.ascontiguousarray(Binv, dtype=np.float64),
                       np.ascontiguousarray(ref, dtype=np.float64), ys, layout.width,
                       np.ascontiguousarray(_STEPS[:k], dtype=np.int64), tcx, tcy,
                       f(1.0 / layout.tile ** 2), f(_KEY_SCALE), np.uint32(_KEY_MAX),
                       _KEY_BITS, idx, dist2)
    return idx, dist2
