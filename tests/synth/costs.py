"""Plane-sweep cost planes with the cases the depth kernels must handle."""

from __future__ import annotations

import numpy as np


def random_costs(shape: tuple[int, ...], seed: int) -> np.ndarray:
    """Random float32 costs (S, H, W) with ties (two decimals), +inf (a window outside a
    source) and pixels no source sees (the first row's first three columns)."""
    rng = np.random.default_rng(seed)
    per = np.round(rng.random(shape), 2).astype(np.float32)
    per[rng.random(shape) < 0.2] = np.inf
    per[:, 0, :3] = np.inf
    return per
