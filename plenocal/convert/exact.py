"""Arithmetic whose result must not depend on where an array sits in memory.

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
