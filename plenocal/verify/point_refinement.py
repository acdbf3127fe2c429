"""Refinement of triangulated 3-D points with every camera held fixed: the bundle
adjustment that COLMAP's triangulator runs between its rounds of track merging and
filtering (``IterativeGlobalRefinement``), for the reprojection error of a calibration
(Table I of the paper, :mod:`plenocal.verify.reprojection`).

With every pose and intrinsic constant and the squared (trivial) loss COLMAP uses there,
the bundle adjustment separates into one three-parameter least-squares problem per
point:

    X* = argmin_X  sum_i || pi(P_i, X) - x_i ||^2,    pi(P, X) = (P_1 X / P_3 X, P_2 X / P_3 X)

over the point's observations ``x_i`` (pixels, the internal convention: pixel centres at
integers) in images with projection matrices ``P_i = K_i [R_i | t_i]``. It is solved here
for all points at once by Levenberg-Marquardt on stacked 3 x 3 normal equations, each
point damped and stopped on its own. Ceres, as COLMAP calls it, solves the same problem
as one sparse system and stops for all points together (gradient tolerance 1, at most 50
iterations): on the default data a 700-view round took 4-8 s there, about 1 s here; run
to tight tolerances, both give the same points (tests/test_reprojection.py).
"""

from __future__ import annotations

import numpy as np

#: iterations per point at most (COLMAP's ``ba_global_max_num_iterations``)
MAX_ITERATIONS = 50
#: a point has converged when its step moves its projections by less than this (RMS over
#: its observations, pixels)
STEP_TOLERANCE_PX = 1e-6
#: Levenberg-Marquardt damping: initial value and bounds
_LAMBDA0, _LAMBDA_MIN, _LAMBDA_MAX = 1e-4, 1e-12, 1e12
#: floor of the damped diagonal (Ceres' ``min_lm_diagonal``)
_MIN_DIAGONAL = 1e-6


def projection_matrices(K: np.ndarray, world_to_cam: np.ndarray) -> np.ndarray:
    """``P = K [R | t]`` (..., 3, 4) of intrinsics ``K`` (..., 3, 3) and world-to-camera
    transforms (..., 4, 4)."""
    return np.asarray(K, float) @ np.asarray(world_to_cam, float)[..., :3, :]


def _project(Pr: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels (u, v) and ``w = P_3 X`` of points ``X`` (n, 3) through the projection
    matrices' entries ``Pr`` (12, n), row-major."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    w = Pr[8] * x + Pr[9] * y + Pr[10] * z + Pr[11]
    u = (Pr[0] * x + Pr[1] * y + Pr[2] * z + Pr[3]) / w
    v = (Pr[4] * x + Pr[5] * y + Pr[6] * z + Pr[7]) / w
    return u, v, w


def refine_points(xyz: np.ndarray, point: np.ndarray, image: np.ndarray, P: np.ndarray,
                  uv: np.ndarray) -> tuple[np.ndarray, int]:
    """Points ``xyz`` (m, 3) refined to the least squared reprojection error of their
    observations: observation ``i`` of point ``point[i]`` (n,) at pixel ``uv[i]`` (n, 2,
    internal convention) in image ``image[i]`` (n,) of projection matrix ``P[image[i]]``
    (P: (c, 3, 4), :func:`projection_matrices`). Every point is a Levenberg-Marquardt
    problem of its own (module docstring); a step that would not lower a point's cost is
    not taken. Returns the refined points and the number of iterations run."""
    X = np.array(xyz, dtype=float, copy=True)
    m = len(X)
    point = np.asarray(point, dtype=np.int64)
    image = np.asarray(image, dtype=np.int64)
    P_flat = np.asarray(P, dtype=float).reshape(-1, 12)
    Pr_all = np.stack([P_flat[:, e][image] for e in range(12)])  # (12, n)
    uv = np.asarray(uv, dtype=float)
    obs_u, obs_v = np.ascontiguousarray(uv[:, 0]), np.ascontiguousarray(uv[:, 1])
    if m == 0 or len(point) == 0:
        return X, 0
    lam = np.full(m, _LAMBDA0)
    u, v, w = _project(Pr_all, X[point])
    ru, rv = u - obs_u, v - obs_v
    cost = np.bincount(point, weights=ru * ru + rv * rv, minlength=m)
    count = np.bincount(point, minlength=m)
    active = count > 0
    compact = np.empty(m, np.int64)  # active point -> its row in this iteration's arrays
    it = 0
    for it in range(1, MAX_ITERATIONS + 1):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            it -= 1
            break
        k = idx.size
        if k == m:
            obs, pc, Pr = slice(None), point, Pr_all
        else:
            compact[idx] = np.arange(k)
            obs = np.flatnonzero(active[point])
            pc, Pr = compact[point[obs]], Pr_all[:, obs]
        ui, vi, wi, rui, rvi = u[obs], v[obs], w[obs], ru[obs], rv[obs]
        # d(u, v)/dX = (P_1 - u P_3, P_2 - v P_3) / w  (their first three entries)
        Ju = [(Pr[a] - ui * Pr[8 + a]) / wi for a in range(3)]
        Jv = [(Pr[4 + a] - vi * Pr[8 + a]) / wi for a in range(3)]
        H = np.empty((k, 3, 3))
        g = np.empty((k, 3))
        for a in range(3):
            g[:, a] = np.bincount(pc, weights=Ju[a] * rui + Jv[a] * rvi, minlength=k)
            for b in range(a, 3):
                H[:, a, b] = np.bincount(pc, weights=Ju[a] * Ju[b] + Jv[a] * Jv[b],
                                         minlength=k)
                H[:, b, a] = H[:, a, b]
        diag = np.clip(np.diagonal(H, axis1=1, axis2=2), _MIN_DIAGONAL, None)
        A = H + (lam[idx][:, None] * diag)[:, :, None] * np.eye(3)
        step = -np.linalg.solve(A, g[:, :, None])[:, :, 0]
        X_new = X[idx] + step
        un, vn, wn = _project(Pr, X_new[pc])
        run, rvn = un - obs_u[obs], vn - obs_v[obs]
        cost_new = np.bincount(pc, weights=run * run + rvn * rvn, minlength=k)
        good = cost_new < cost[idx]
        gi = idx[good]
        X[gi] = X_new[good]
        cost[gi] = cost_new[good]
        take = good[pc]
        at = np.arange(len(point))[obs][take] if k < m else np.flatnonzero(take)
        u[at], v[at], w[at], ru[at], rv[at] = un[take], vn[take], wn[take], run[take], rvn[take]
        lam[gi] = np.maximum(lam[gi] / 3.0, _LAMBDA_MIN)
        lam[idx[~good]] *= 2.0
        # the step's motion in the images, RMS over the point's observations (pixels^2)
        moved = np.einsum("ki,kij,kj->k", step, H, step) / count[idx]
        done = (moved <= STEP_TOLERANCE_PX ** 2) | (lam[idx] > _LAMBDA_MAX)
        active[idx[done]] = False
    return X, it
