"""Registration B against the ground truth: one N x N set of a ``rig.json`` beside the
simulator's traced cameras of the same set (:mod:`plenocal.simulate.groundtruth`),
both relative to their central view: baseline, principal-point-equivalent shift,
alpha-equivalent, view centres and rotations. Used by :mod:`plenocal.verify.gt_errors`
and the tests of registration B.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from plenocal.artifacts.rig import RigB
from plenocal.camera import PinholeCamera, invert_pose, rotation_angle_deg
from plenocal.names import central_view, parse_view, view_names
from plenocal.viewgeom import view_position


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    A = np.stack([x, np.ones_like(x)], axis=1)
    return float(np.linalg.lstsq(A, y, rcond=None)[0][0])


def set_geometry(views: Mapping[str, tuple[np.ndarray, np.ndarray]], n_views: int,
                 width: int, height: int) -> dict:
    """Baseline, principal-point-equivalent shift and alpha-equivalent of one set.

    ``views``: (K, pose relative to the central view, metres). The pp-equivalent of a
    view is the pixel where the central view's optical axis direction lands in it
    (K R^T (0, 0, 1)): the shifted principal point for the exact model,
    ``c + F_m tan(h alpha)`` for the paper's rotated views; its slope per step gives
    ``alpha_eq = atan(slope / f)``."""
    hs, vs, xs, ys, us, ws, fs = [], [], [], [], [], [], []
    cx0, cy0 = (width - 1) / 2.0, (height - 1) / 2.0
    for name, (K, M) in views.items():
        h, v = view_position(*parse_view(name), n_views)
        d = M[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        uvw = K @ d
        hs.append(h)
        vs.append(v)
        xs.append(M[0, 3])
        ys.append(M[1, 3])
        us.append(uvw[0] / uvw[2] - cx0)
        ws.append(uvw[1] / uvw[2] - cy0)
        fs.append(K[0, 0])
    hs, vs = np.array(hs, float), np.array(vs, float)
    Bx, By = _slope(hs, np.array(xs)), _slope(vs, np.array(ys))
    px, py = _slope(hs, np.array(us)), _slope(vs, np.array(ws))
    f = float(np.mean(fs))
    return {"B_x_m": Bx, "B_y_m": By, "B_m": (Bx + By) / 2, "pp_shift_x_px": px,
            "pp_shift_y_px": py, "pp_shift_px": (px + py) / 2, "focal_px": f,
            "alpha_equivalent": math.atan((px + py) / 2 / f)}


def _worse(pair: list[float | None]) -> float | None:
    """The one of the two axes' errors that is larger in size (its sign kept)."""
    vals = [v for v in pair if v is not None]
    return max(vals, key=abs) if vals else None


def compare_with_truth(rig: Mapping, truth: Mapping[str, PinholeCamera]) -> dict:
    """Compare a ``rig.json`` document with ground-truth cameras of one N x N set
    (``truth``: view name -> camera in any world frame, metres).

    Both sets are expressed relative to their central view. Reports the baseline,
    pp-equivalent shift and alpha-equivalent of each with their errors, per axis
    (``*_xy``) and the larger of the two (the headline figures), the RMSE of the view
    centres (mm) and the largest rotation difference (degrees)."""
    n = int(rig["n_views"])
    W, H = int(rig["width"]), int(rig["height"])
    centre = central_view(n)
    missing = sorted(set(view_names(n)) - set(truth))
    if missing:
        raise ValueError(f"ground truth lacks views {', '.join(missing)} of the {n}x{n} set")
    to_c = invert_pose(truth[centre].cam_to_world)
    gt = {k: (truth[k].K, to_c @ truth[k].cam_to_world) for k in view_names(n)}
    est = RigB(rig).view_poses()
    g_gt = set_geometry(gt, n, W, H)
    g_est = set_geometry(est, n, W, H)
    d_c = np.array([est[k][1][:3, 3] - gt[k][1][:3, 3] for k in view_names(n)])
    rot = [rotation_angle_deg(est[k][1][:3, :3], gt[k][1][:3, :3]) for k in view_names(n)]
    # per axis, and the worse of the two: a mean over x and y would let errors of opposite
    # signs in the two axes cancel
    err_b = [g_est[f"B_{a}_m"] / g_gt[f"B_{a}_m"] - 1.0 for a in "xy"]
    err_pp = [g_est[f"pp_shift_{a}_px"] - g_gt[f"pp_shift_{a}_px"] for a in "xy"]
    f_gt, f_est = g_gt["focal_px"], g_est["focal_px"]
    err_alpha = [math.atan(g_est[f"pp_shift_{a}_px"] / f_est)
                 / math.atan(g_gt[f"pp_shift_{a}_px"] / f_gt) - 1.0
                 if g_gt[f"pp_shift_{a}_px"] else None for a in "xy"]
    return {
        "truth": g_gt, "estimate": g_est,
        "rel_err_B": _worse(err_b), "rel_err_B_xy": err_b,
        "rel_err_alpha": _worse(err_alpha), "rel_err_alpha_xy": err_alpha,
        "err_pp_shift_px": _worse(err_pp), "err_pp_shift_xy_px": err_pp,
        "centre_rmse_mm": float(np.sqrt((d_c ** 2).sum(axis=1).mean()) * 1000.0),
        "rotation_max_deg": float(max(rot)),
    }

