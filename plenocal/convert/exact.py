"""Arithmetic whose result must not depend on where an array sits in memory, and OpenCV
calls made safe for arrays of any size.

The same inputs must give byte-identical outputs (Snakemake's checksums, reruns on a
cluster). OpenCV's ``cv2.magnitude`` does not: its vector and scalar paths round the last
bit differently, and which elements take which path depends on the arrays' alignment, so
the same frame converted twice gave a grid 2e-9 px apart, other patch sizes and views
1-2 levels apart (Boys2, one run in two). numpy's element-wise float operations are
IEEE-exact on every path.
"""

from __future__ import annotations

import numpy as np


def magnitude(x: np.ndarray, y: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``sqrt(x^2 + y^2)`` element-wise (float32 for float32 inputs; into ``out`` where
    given), the same bits wherever the arrays sit (:func:`cv2.magnitude`'s replacement:
    its result changed with the output's alignment)."""
    out = np.multiply(x, x, out=out)
    out += np.multiply(y, y)
    return np.sqrt(out, out=out)


#: OpenCV's remap takes maps and images of fewer than 2^15 - 1 rows and columns
_REMAP_MAX = 32767 - 1


def remap(src: np.ndarray, map_x: np.ndarray, map_y: np.ndarray, interpolation: int,
          **kwargs) -> np.ndarray:
    """``cv2.remap`` for maps of any number of rows: the per-lens sample maps of a 40-MP
    sensor (Raytrix R42: 7716 x 5364 px, about 39,000 lenses of 35 px) have more rows than
    OpenCV allows (2^15 - 1), so they are sampled in slices of rows (every output pixel
    depends on its own map entries only: the same numbers as one call)."""
    import cv2  # noqa: PLC0415

    n = map_x.shape[0]
    if n <= _REMAP_MAX:
        return cv2.remap(src, map_x, map_y, interpolation, **kwargs)
    parts = [cv2.remap(src, np.ascontiguousarray(map_x[a:a + _REMAP_MAX]),
                       np.ascontiguousarray(map_y[a:a + _REMAP_MAX]), interpolation, **kwargs)
             for a in range(0, n, _REMAP_MAX)]
    return np.concatenate(parts, axis=0)
