"""The hexagonal microlens grid built from a Raytrix calibration.

A lens is addressed by integer lattice coordinates ``(i, j)``; its micro-image
centre in image pixels (x right, y down, pixel centres at integers) is::

    origin + i * A1 + j * A2,   origin = ((W-1)/2 + offset.x, (H-1)/2 - offset.y)

with ``A1 = D R(theta) (1, 0)`` and ``A2 = D R(theta) (1/2, sqrt(3)/2)`` written in
the file's y-up frame and flipped to image coordinates; ``theta`` is the file's
``rotation``. A hexagonal lattice repeats every 60 degrees, so files that store the
rotation inside ``lens_base_x/y`` (rotation pi/2 with rotated base vectors) and files
that store it beside them (TempleBoat: base vectors unrotated, rotation 0.0007 rad)
describe the same lattice; the lens types are read in the frame of the base vectors.

A grid measured on the image (:func:`plenocal.convert.gridcheck.refine_grid`) replaces
the file's origin and lattice vectors by fitted ones (``lattice=(origin, A)``, an affine
lattice); lens indices ``(i, j)`` and lens types stay those of the file.

Lens types: the type-0 lenses form the centred rectangular lattice whose cell is
``|sub_grid_base|`` (3 x sqrt(3) lens units for rows of lenses); type ``t`` is that
lattice shifted by its ``offset``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from plenocal.io.raytrix import CalibError, RayCalib

SENSOR_BORDERS = ("top", "bottom", "left", "right")
HEX_STEPS = np.array([(1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1)], dtype=np.int64)


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _wrap60(angle: float) -> float:
    """Reduce an angle to (-30, 30] degrees (hexagonal symmetry)."""
    p = math.pi / 3
    a = math.fmod(angle, p)
    if a > p / 2:
        a -= p
    elif a <= -p / 2:
        a += p
    return a


@dataclass
class MicrolensGrid:
    """Micro-image centres of every lens whose centre lies on the sensor."""

    calib: RayCalib
    width: int
    height: int
    # (origin (2,), A (2, 2) with lattice vectors as columns), image pixels: a measured
    # lattice replacing the file's (None: the file's)
    lattice: tuple[np.ndarray, np.ndarray] | None = None
    ij: np.ndarray = field(init=False)  # (n, 2) int lattice coordinates
    centres: np.ndarray = field(init=False)  # (n, 2) float image coordinates (x, y)
    types: np.ndarray = field(init=False)  # (n,) lens type id
    lattice_xy: np.ndarray = field(init=False)  # (n, 2) lens units in the lattice frame
    neighbours: np.ndarray = field(init=False)  # (n, 6) index of the neighbour or -1

    def __post_init__(self) -> None:
        c = self.calib
        D = c.diameter
        origin = np.array([(self.width - 1) / 2 + c.offset[0],
                           (self.height - 1) / 2 - c.offset[1]])
        R = _rot(c.rotation)
        flip = np.diag([1.0, -1.0])
        A_file = (flip @ R @ np.array([[1.0, 0.5], [0.0, math.sqrt(3) / 2]])) * D  # columns
        if self.lattice is None:
            self.origin, self.A = origin, A_file
        else:
            self.origin = np.asarray(self.lattice[0], dtype=float).reshape(2).copy()
            self.A = np.asarray(self.lattice[1], dtype=float).reshape(2, 2).copy()
            if abs(np.linalg.det(self.A)) < 1e-6 * D * D:
                raise CalibError(f"{c.source}: measured lattice is degenerate ({self.A.tolist()})")
        # unit vectors of the lattice frame in image coordinates
        self.e1 = self.A[:, 0] / np.linalg.norm(self.A[:, 0])
        self.e2 = np.array([-self.e1[1], self.e1[0]])  # e1 turned +90 deg in y-down image
        self.rotation_image = math.atan2(self.e1[1], self.e1[0])

        corners = np.array([[0, 0], [self.width - 1, 0], [0, self.height - 1],
                            [self.width - 1, self.height - 1]], dtype=float) - self.origin
        Ainv = np.linalg.inv(self.A)
        cij = corners @ Ainv.T
        lo = np.floor(cij.min(axis=0)).astype(int) - 1
        hi = np.ceil(cij.max(axis=0)).astype(int) + 1
        ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1),
                             indexing="ij")
        ij = np.stack([ii.ravel(), jj.ravel()], axis=1)
        centres = self.centres_at(ij)
        on = ((centres[:, 0] >= 0) & (centres[:, 0] <= self.width - 1)
              & (centres[:, 1] >= 0) & (centres[:, 1] <= self.height - 1))
        # row-major order of the image: sort by y then x, for stable, readable output
        idx = np.flatnonzero(on)
        order = np.lexsort((centres[idx, 0], np.round(centres[idx, 1], 3)))
        idx = idx[order]
        self.ij = ij[idx]
        self.centres = centres[idx]
        rel = self.centres - self.origin
        self.lattice_xy = np.stack([rel[:, 0] * self.e1[0] + rel[:, 1] * self.e1[1],
                                    rel[:, 0] * self.e2[0] + rel[:, 1] * self.e2[1]],
                                   axis=1) / D
        # lens types from the lattice indices on the file's lattice (the same lenses for a
        # measured lattice as for the file's)
        self.types = self._lens_types(
            (self.ij[:, :1] * A_file[:, 0] + self.ij[:, 1:] * A_file[:, 1]) / D)
        self.neighbours = self._neighbours()

    def centres_at(self, ij: np.ndarray) -> np.ndarray:
        """(n, 2) image coordinates of the lattice points ``ij`` (n, 2), whether or not
        they lie on the sensor. The products are written out, not BLAS: OpenBLAS's
        kernels round differently with the thread count, and the centres must be the
        same bit for bit on every machine."""
        return self.origin + ij[:, :1] * self.A[:, 0] + ij[:, 1:] * self.A[:, 1]

    # ------------------------------------------------------------------
    @property
    def diameter(self) -> float:
        return self.calib.diameter

    def __len__(self) -> int:
        return len(self.centres)

    def _lens_types(self, rel_lens_units: np.ndarray) -> np.ndarray:
        c = self.calib
        n = len(rel_lens_units)
        if len(c.lens_types) == 1:
            return np.zeros(n, dtype=np.int64)
        # into the file's base-vector frame (y up), undoing any rotation not in the bases
        w = rel_lens_units * np.array([1.0, -1.0])
        base_angle = math.atan2(c.lens_base_x[1], c.lens_base_x[0])
        delta = _wrap60(c.rotation - base_angle)
        p = w @ _rot(-delta).T
        assert c.sub_grid_base is not None
        Sx, Sy = abs(c.sub_grid_base[0]), abs(c.sub_grid_base[1])
        if Sx < 0.5 or Sy < 0.5:
            raise CalibError(f"{c.source}: sub_grid_base: cell too small ({Sx}, {Sy})")
        types = np.full(n, -1, dtype=np.int64)
        tol = 0.15
        for t in c.lens_types:
            d = p - np.array(t.offset)
            a, b = d[:, 0] / Sx, d[:, 1] / Sy
            on_cell = (np.abs(a - np.round(a)) < tol / Sx) & (np.abs(b - np.round(b)) < tol / Sy)
            a2, b2 = a - 0.5, b - 0.5
            on_centre = ((np.abs(a2 - np.round(a2)) < tol / Sx)
                         & (np.abs(b2 - np.round(b2)) < tol / Sy))
            hit = on_cell | on_centre
            clash = hit & (types >= 0)
            if clash.any():
                raise CalibError(f"{c.source}: lens_type: lens types {int(types[clash][0])} "
                                 f"and {t.id} claim the same lens")
            types[hit] = t.id
        if (types < 0).any():
            raise CalibError(f"{c.source}: lens_type: {int((types < 0).sum())} lenses match no "
                             "lens type (offsets inconsistent with sub_grid_base)")
        return types

    def _neighbours(self) -> np.ndarray:
        lo = self.ij.min(axis=0)
        shape = self.ij.max(axis=0) - lo + 3
        table = np.full(tuple(shape), -1, dtype=np.int64)
        local = self.ij - lo + 1
        table[local[:, 0], local[:, 1]] = np.arange(len(self.ij))
        nb = np.empty((len(self.ij), 6), dtype=np.int64)
        for k, step in enumerate(HEX_STEPS):
            q = local + step
            ok = (q[:, 0] >= 0) & (q[:, 0] < shape[0]) & (q[:, 1] >= 0) & (q[:, 1] < shape[1])
            nb[:, k] = -1
            nb[ok, k] = table[q[ok, 0], q[ok, 1]]
        return nb

    @property
    def neighbour_vectors(self) -> np.ndarray:
        """(6, 2) image-space offsets from a lens to its neighbours, order of HEX_STEPS."""
        return HEX_STEPS @ self.A.T

    def inside(self, margin: float | None = None) -> np.ndarray:
        """Lenses whose micro image (radius D/2 + margin) lies wholly on the sensor."""
        r = self.diameter / 2 if margin is None else self.diameter / 2 + margin
        x, y = self.centres[:, 0], self.centres[:, 1]
        return (x - r >= -0.5) & (x + r <= self.width - 0.5) & (y - r >= -0.5) & (
            y + r <= self.height - 0.5)

    def border_distance(self, border: str) -> np.ndarray:
        """(n,) each micro-image centre's distance (pixels) from the sensor's ``border``:
        ``top``, ``bottom``, ``left`` or ``right`` (to the outermost pixel centres)."""
        x, y = self.centres[:, 0], self.centres[:, 1]
        if border not in SENSOR_BORDERS:
            raise ValueError(f"border must be one of {', '.join(SENSOR_BORDERS)} "
                             f"(got {border!r})")
        return {"top": y, "bottom": self.height - 1 - y, "left": x,
                "right": self.width - 1 - x}[border]

    def lit(self, insets_px: Mapping[str, float] | None = None) -> np.ndarray:
        """(n,) bool: the lenses at least ``insets_px[border]`` from each border named
        (all of them without insets): the lenses whose micro images the main lens does
        not cut (:mod:`plenocal.convert.bordercut`)."""
        keep = np.ones(len(self), bool)
        for border, inset in (insets_px or {}).items():
            if inset > 0:
                keep &= self.border_distance(border) >= inset
        return keep

    def lattice_to_image(self, vec: np.ndarray) -> np.ndarray:
        """Vectors in the lattice frame (pixels along e1, e2) to image-space vectors."""
        vec = np.asarray(vec, dtype=float)
        return vec[..., :1] * self.e1 + vec[..., 1:2] * self.e2

    def image_to_lattice(self, vec: np.ndarray) -> np.ndarray:
        vec = np.asarray(vec, dtype=float)
        return np.stack([vec @ self.e1, vec @ self.e2], axis=-1)
