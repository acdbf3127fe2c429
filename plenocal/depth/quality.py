"""Depth quality against ground truth: share of valid pixels and share within a
relative tolerance (1 %) of the true z-depth."""

from __future__ import annotations

import numpy as np


def depth_quality(est: np.ndarray, gt: np.ndarray, tol: float = 0.01,
                  border: int = 0) -> dict:
    """Scores over the pixels with a ground truth (gt > 0), excluding ``border``:

    valid_share: estimate present; within_share: present and |est - gt| <= tol gt
    (both over the ground-truth pixels); within_of_valid: within among the valid;
    median_rel_error over the valid pixels."""
    est = np.asarray(est, np.float64)
    gt = np.asarray(gt, np.float64)
    if est.shape != gt.shape:
        raise ValueError(f"depth quality: estimate {est.shape} and ground truth {gt.shape} "
                         "differ in size")
    if border > 0:
        est = est[border:-border, border:-border]
        gt = gt[border:-border, border:-border]
    have = gt > 0
    valid = have & (est > 0)
    rel = np.abs(est - gt) / np.where(have, gt, 1.0)
    within = valid & (rel <= tol)
    n = max(int(have.sum()), 1)
    nv = max(int(valid.sum()), 1)
    return {
        "pixels": int(have.sum()),
        "valid_share": float(valid.sum() / n),
        "within_share": float(within.sum() / n),
        "within_of_valid": float(within.sum() / nv),
        "median_rel_error": float(np.median(rel[valid])) if valid.any() else None,
        "tolerance": tol,
    }
