"""Which sensor point each output pixel of subaperture view (r, c) samples.

This is the one piece of geometry shared by the converter (it renders with it),
the ground truth (it traces the chief rays it selects) and registration B's exact
model (which follows from it). It depends on the grid and the convert settings
only, never on image content: the per-lens patch size enters as an argument.

Layout. Every lens whose whole micro image lies on the sensor ("used" lens) owns a
tile of ``T x T`` output pixels (the tile size) centred at::

    o_i = (lattice_xy_i - axis) * T + ((W_v - 1) / 2, (H_v - 1) / 2)

where ``lattice_xy`` are lens positions in lens units in the lattice frame (so a
rotated MLA gives upright views) and ``axis`` is the sensor centre in the same
frame: the optical axis lands on the centre pixel of every view's tile grid, which
is what registration A assumes (principal point at the image centre) for the
central view. ``W_v`` and ``H_v`` are odd and chosen symmetric about the axis so
that every output pixel lies inside the span of used lens centres.

Sampling. View (r, c) of an N x N set has the offset
``q_rc = ((c - (N-1)/2) q, (r - (N-1)/2) q)`` (pixels, lattice frame) from the
micro-image centre, with ``q = D' sin(45 deg) / N`` by default (the paper). Output
pixel ``u`` in the tile of lens ``i`` whose patch size is ``P_i`` samples::

    m_i + R (q_rc - (u - o_i) * P_i / T)

``R`` maps lattice-frame vectors to the image; the minus sign is the 180-degree
turn of every micro image (Keplerian relay). The tile centre ``u = o_i`` samples
``m_i + R q_rc`` whatever ``P_i`` is: its chief ray defines the view's pinhole.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plenocal.grid import MicrolensGrid
from plenocal.optics import view_spacing


def view_name(r: int, c: int) -> str:
    return f"{r}_{c}"


def parse_view(name: str) -> tuple[int, int]:
    r, c = name.split("_")
    return int(r), int(c)


def view_names(n: int) -> list[str]:
    return [view_name(r, c) for r in range(n) for c in range(n)]


def central_view(n: int) -> str:
    h = (n - 1) // 2
    return view_name(h, h)


def view_position(r: int, c: int, n: int) -> tuple[int, int]:
    """(h, v): the view's step from the centre, horizontal and vertical (Eq. 4)."""
    h = (n - 1) // 2
    return c - h, r - h


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
    e1: np.ndarray  # lattice frame in image coordinates
    e2: np.ndarray
    basis: np.ndarray  # (2, 2) rows: output-pixel steps of lattice steps (1, 0) and (0, 1)

    def offset(self, r: int, c: int) -> np.ndarray:
        """q_rc in the lattice frame (pixels)."""
        h, v = view_position(r, c, self.n_views)
        return np.array([h * self.q, v * self.q])

    def offset_image(self, r: int, c: int) -> np.ndarray:
        """q_rc as an image-space vector on the sensor."""
        o = self.offset(r, c)
        return o[0] * self.e1 + o[1] * self.e2

    def chief_sensor_points(self, r: int, c: int) -> np.ndarray:
        """Sensor points sampled by the tile centres of view (r, c): m_i + R q_rc."""
        return self.lens_centres + self.offset_image(r, c)

    def sensor_points(self, r: int, c: int, lens: np.ndarray, out_xy: np.ndarray,
                      patch: np.ndarray) -> np.ndarray:
        """Sensor positions sampled by output pixels ``out_xy`` (..., 2) of view (r, c)
        through used-lens indices ``lens`` (...) with patch sizes ``patch`` (...)."""
        d = (out_xy - self.tile_centres[lens]) * (patch / self.tile)[..., None]
        v = self.offset(r, c) - d
        return self.lens_centres[lens] + v[..., :1] * self.e1 + v[..., 1:2] * self.e2


def make_layout(grid: MicrolensGrid, n_views: int, tile: int, q: float | None = None,
                margin: float = 0.0) -> ViewLayout:
    """Build the output layout of the N x N views of one lenslet image."""
    if n_views < 1 or n_views % 2 == 0:
        raise ValueError(f"the number of views per side must be odd (got {n_views})")
    if tile < 1:
        raise ValueError(f"tile size must be >= 1 (got {tile})")
    if q is None:
        q = view_spacing(grid.calib.safe_diameter, n_views)
    used = np.flatnonzero(grid.inside(margin))
    if len(used) < 4:
        raise ValueError("fewer than 4 microlenses lie wholly on the sensor: does calib.xml "
                         "belong to this lenslet image?")
    lxy = grid.lattice_xy[used]
    sensor_centre = np.array([(grid.width - 1) / 2, (grid.height - 1) / 2])
    axis = grid.image_to_lattice(sensor_centre - grid.origin) / grid.diameter
    lo, hi = lxy.min(axis=0), lxy.max(axis=0)
    half = np.minimum(axis - lo, hi - axis) * tile
    if (half <= 1).any():
        raise ValueError("the sensor centre lies outside the microlens grid")
    size = 2 * np.floor(half).astype(int) + 1
    width, height = int(size[0]), int(size[1])
    centre_out = np.array([(width - 1) / 2, (height - 1) / 2])
    tile_centres = (lxy - axis) * tile + centre_out
    return ViewLayout(
        n_views=n_views, tile=int(tile), q=float(q), width=width, height=height,
        lens_index=used, tile_centres=tile_centres, lens_centres=grid.centres[used],
        e1=grid.e1.copy(), e2=grid.e2.copy(),
        basis=grid.image_to_lattice(grid.A.T) / grid.diameter * tile,
    )


def nearest_lenses(layout: ViewLayout, k: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """For every output pixel, up to ``k`` used lenses whose tiles may cover it.

    Returns (lens index into the layout (H, W, k), -1 where none; squared distance to
    the tile centre in tile units (H, W, k)). Candidates are the lens whose tile centre
    is nearest and its six lattice neighbours, so any weight of radius <= 1 tile is
    complete.
    """
    T = layout.tile
    ys, xs = np.mgrid[0:layout.height, 0:layout.width].astype(np.float64)
    c0 = layout.tile_centres
    ref = c0[0]
    B = layout.basis.T  # columns: output-pixel vectors of the two lattice steps
    Binv = np.linalg.inv(B)
    lat = np.rint((c0 - ref) @ Binv.T).astype(np.int64)
    lo = lat.min(axis=0) - 2
    shape = lat.max(axis=0) - lo + 3
    table = np.full(tuple(shape), -1, dtype=np.int64)
    table[lat[:, 0] - lo[0], lat[:, 1] - lo[1]] = np.arange(len(c0))
    pix = np.stack([xs - ref[0], ys - ref[1]], axis=-1)
    a = np.rint(pix @ Binv.T).astype(np.int64)
    steps = np.array([(0, 0), (1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1),
                      (1, 1), (-1, -1), (2, -1), (-2, 1), (1, -2), (-1, 2)])[: max(k, 1)]
    idx = np.full((layout.height, layout.width, len(steps)), -1, dtype=np.int64)
    dist2 = np.full(idx.shape, np.inf)
    for n, st in enumerate(steps):
        q = a + st - lo
        ok = (q[..., 0] >= 0) & (q[..., 0] < shape[0]) & (q[..., 1] >= 0) & (q[..., 1] < shape[1])
        li = np.full(q.shape[:2], -1, dtype=np.int64)
        li[ok] = table[q[ok][:, 0], q[ok][:, 1]]
        idx[..., n] = li
        have = li >= 0
        diff = np.stack([xs, ys], axis=-1)[have] - c0[li[have]]
        dist2[..., n][have] = (diff ** 2).sum(axis=1) / T ** 2
    return idx, dist2
