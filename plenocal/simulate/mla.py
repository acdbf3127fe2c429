"""The simulated MLA as Raytrix describes it: ``calib.xml`` (RayCalibData) and the
lens type of every sensor pixel.

Raytrix's layout, read off the real files in ``shared/fixtures/raytrix-calib`` and
``shared/real/frames``: a grid turned by pi/2 is stored as ``rotation`` = pi/2 *and*
base vectors turned with it (``lens_base_x`` = (0, 1), ``lens_base_y`` =
(0.866, 0.5), ``sub_grid_base`` = (1.732, 3)); an unturned grid as (1, 0),
(0.5, -0.866), (3, -1.732); a slightly turned one (TempleBoat, 0.0007 rad) keeps
the base vectors of the nearest quarter turn and states the rest in ``rotation``.
The three lens types of a multi-focus MLA are interleaved: type 0 at offset (0, 0)
of the centred rectangular sub-grid, types 1 and 2 one lens step along
``+lens_base_x`` and ``-lens_base_x``. Depth ranges: each type's depth of field (the
virtual depths whose blur disc stays within ``depth_of_field_px`` pixels), with the
outer ends left open as Raytrix writes them (from virtual depth 1, to 100); a single
type's range is the scene's depth range with a 15 % margin, in virtual depths as the
file's readers take them (``P = D / v``:
:meth:`plenocal.optics.PlenopticOptics.measured_virtual_depth`).

The lens types of the pixels come from :class:`plenocal.grid.MicrolensGrid` built
from that very file, so the simulator and the reader agree by construction.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plenocal.grid import MicrolensGrid
from plenocal.io.raytrix import LensType, RayCalib
from plenocal.optics import PlenopticOptics

SQRT3 = math.sqrt(3.0)
OPEN_NEAR = 1.0  # Raytrix's open ends of the outer lens types' depth ranges
OPEN_FAR = 100.0


def _turn(beta: float, v: tuple[float, float]) -> tuple[float, float]:
    """``v`` turned by ``beta`` (y up), rounded to the file's 12 decimals, no -0."""
    c, s = math.cos(beta), math.sin(beta)
    return (round(c * v[0] - s * v[1], 12) + 0.0, round(s * v[0] + c * v[1], 12) + 0.0)


def base_angle(rotation: float) -> float:
    """The quarter turn nearest to ``rotation``: the frame of the file's base vectors."""
    return round(rotation / (math.pi / 2)) * (math.pi / 2)


def type_depth_ranges(optics: PlenopticOptics, blur_px: float) -> list[tuple[float, float]]:
    """(min, max) |virtual depth| per lens type: its depth of field for ``blur_px``,
    the nearest type's min and the farthest type's max opened to 1 and 100."""
    ranges = [optics.depth_of_field(i, blur_px) for i in range(optics.lens_types)]
    sharp = [1.0 / abs(optics.type_kappa(i)) for i in range(optics.lens_types)]
    near, far = int(np.argmin(sharp)), int(np.argmax(sharp))
    out = []
    for i, (lo, hi) in enumerate(ranges):
        if i == near:
            lo = min(lo, OPEN_NEAR)
        if i == far or not math.isfinite(hi):
            hi = max(hi, OPEN_FAR) if math.isfinite(hi) else OPEN_FAR
        out.append((round(lo, 6), round(hi, 6)))
    return out


def make_calib(sim: dict, optics: PlenopticOptics) -> RayCalib:
    """The RayCalibData of the simulated MLA (micro-image centres, lens types)."""
    mla = sim["mla"]
    rotation = float(mla["rotation_rad"])
    beta = base_angle(rotation)
    ox, oy = mla["offset_px"]
    if optics.lens_types == 1:
        # the scene's depth range with a margin, as the file's readers take virtual depths
        # (P = D / v: optics.measured_virtual_depth). The physical a / s put the far end
        # of tspc-like's scene past the range (P 14.27 px against a smallest candidate of
        # 14.72): its background's lenses matched at the search's end, their sizes filled
        near, far = sim["scene"]["near_m"], sim["scene"]["far_m"]
        v = sorted(float(optics.measured_virtual_depth(z)) for z in (near, far))
        types: tuple[LensType, ...] = (
            LensType(0, (0.0, 0.0), round(0.85 * v[0], 6), round(1.15 * v[1], 6)),)
        sub = None
    elif optics.lens_types == 3:
        step = _turn(beta, (1.0, 0.0))
        offsets = [(0.0, 0.0), step, (-step[0] + 0.0, -step[1] + 0.0)]
        ranges = type_depth_ranges(optics, float(mla["depth_of_field_px"]))
        types = tuple(LensType(i, offsets[i], *ranges[i]) for i in range(3))
        sub = _turn(beta, (3.0, -SQRT3))
    else:
        raise ValueError(f"mla.lens_types: 1 or 3 (Raytrix interleaving), not "
                         f"{optics.lens_types}")
    return RayCalib(
        diameter=optics.micro_image_pitch_px, offset=(float(ox), float(oy)),
        rotation=rotation, lens_border=mla["lens_border_px"],
        lens_base_x=_turn(beta, (1.0, 0.0)), lens_base_y=_turn(beta, (0.5, -SQRT3 / 2)),
        lens_types=types, sub_grid_base=sub,
        tcp=abs(float(optics.virtual_depth(optics.focus_distance))), is_real=0,
    )


def lens_type_map(calib: RayCalib, lens_map: np.ndarray) -> np.ndarray:
    """(H, W) lens type of every pixel, from the micro-image centres ``lens_map``
    (H, W, 2) of the lenses the pixels lie under. Types come from a MicrolensGrid of
    ``calib`` on a sensor grown by two lens pitches on each side (lenses whose centre
    lies off the sensor light its rim), which keeps the lattice indices."""
    height, width = lens_map.shape[:2]
    if len(calib.lens_types) == 1:
        return np.zeros((height, width), dtype=np.int64)
    pad = int(math.ceil(2 * calib.diameter))
    big = MicrolensGrid(calib, width + 2 * pad, height + 2 * pad)
    lo = big.ij.min(axis=0)
    table = np.full(tuple(big.ij.max(axis=0) - lo + 1), -1, dtype=np.int64)
    table[big.ij[:, 0] - lo[0], big.ij[:, 1] - lo[1]] = big.types
    out = np.empty((height, width), dtype=np.int64)
    _lookup_types(np.ascontiguousarray(lens_map, dtype=np.float64), big.origin - pad,
                  np.ascontiguousarray(np.linalg.inv(big.A)), lo.astype(np.int64), table, out)
    if (out < 0).any():
        raise ValueError(f"{int((out < 0).sum())} pixels lie under no lens of the grid")
    return out


@njit(cache=True)
def _lookup_types(lens_map, origin, Ainv, lo, table, out):
    """Per pixel: lattice index of its lens centre, then that lens's type (-1: none)."""
    for row in range(lens_map.shape[0]):
        for col in range(lens_map.shape[1]):
            rx = lens_map[row, col, 0] - origin[0]
            ry = lens_map[row, col, 1] - origin[1]
            i = int(round(Ainv[0, 0] * rx + Ainv[0, 1] * ry)) - lo[0]
            j = int(round(Ainv[1, 0] * rx + Ainv[1, 1] * ry)) - lo[1]
            if 0 <= i < table.shape[0] and 0 <= j < table.shape[1]:
                out[row, col] = table[i, j]
            else:
                out[row, col] = -1
