"""The converted views' geometry against the simulator's true cameras, with no adjustment
(issue 32: "The dense lean: where it is" in BENCHMARKS.md).

A textured patch of view 1 at pixel ``u``, whose true depth ``z`` is known, shows the point
``X = C_1 + z R_1 K_1^{-1} [u, 1]``; the true camera of view 2 predicts where view 2 shows
it (:func:`predict`). Where the views are exactly the true pinhole cameras the patch is
found there (:func:`match_patches`); what is found elsewhere, fitted with one parameter,
says what the views do differently:

* :func:`focal_scale`: every view's focal length scaled by ``1 + eps`` (about its
  principal point), each pair's own constant shift removed (a principal point's worth,
  which the calibration frees): the views' magnification against the truth's, i.e. the
  focal length a calibration of these views should find;
* :func:`parallax_ratio`: the offsets' slope in inverse depth over the prediction's, the
  parallax the views show against the truth's (within a set: the baselines the views
  behave as if they had).

Conventions: internal (:mod:`plenocal.camera`: OpenCV axes, pixel centres at integers).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import cv2
import numpy as np

from plenocal.camera import PinholeCamera

#: parallax_ratio's least parallax over the patches' depths (px) along an axis to compare
MIN_PARALLAX_PX = 0.05


def _scaled(cam: PinholeCamera, eps: float) -> PinholeCamera:
    K = np.array(cam.K, dtype=float)
    K[0, 0] *= 1.0 + eps
    K[1, 1] *= 1.0 + eps
    return dataclasses.replace(cam, K=K)


def predict(cam1: PinholeCamera, cam2: PinholeCamera, uv: np.ndarray, z: np.ndarray,
            eps: float = 0.0) -> np.ndarray:
    """Pixels (n, 2) of view 2 that show view 1's pixels ``uv`` (n, 2) at z-depth ``z``
    (n,), both cameras' focal lengths scaled by ``1 + eps``."""
    return _scaled(cam2, eps).project(_scaled(cam1, eps).unproject(uv, z))[0]


def _parabola(a: float, b: float, c: float) -> float:
    den = a - 2.0 * c + b
    return 0.5 * (a - b) / den if den != 0 else 0.0


def match_patches(img1: np.ndarray, img2: np.ndarray, uv: np.ndarray, pred: np.ndarray,
                  radius: int = 10, search: int = 4, min_peak: float = 0.95,
                  min_std: float = 0.02, depth: np.ndarray | None = None,
                  max_depth_step: float = 0.01) -> np.ndarray:
    """Where view 2 (``img2``, grey) shows the ``(2 radius + 1)``-square patch of view 1
    (``img1``) at each integer pixel ``uv`` (n, 2), searched within ``search`` px of
    ``pred`` (n, 2) by normalised correlation, sub-pixel by a parabola through the peak:
    (n, 2), NaN where the patch is flat (standard deviation under ``min_std`` of the
    image's range), the peak is under ``min_peak`` or on the search window's edge, the
    window leaves the image, or (``depth``: view 1's depth map) the patch's depth varies
    by more than ``max_depth_step`` of itself (a depth edge: the patch's centre is not
    what the match follows)."""
    out = np.full((len(uv), 2), np.nan)
    H1, W1 = img1.shape
    H2, W2 = img2.shape
    r, s = int(radius), int(search)
    rng = float(max(img1.max() - img1.min(), 1e-9))
    a = np.asarray(img1, dtype=np.float32)
    b = np.asarray(img2, dtype=np.float32)
    for k, ((x, y), (px, py)) in enumerate(zip(np.asarray(uv, int), pred, strict=True)):
        ix, iy = int(round(px)), int(round(py))
        if not (r <= x < W1 - r and r <= y < H1 - r and r + s <= ix < W2 - r - s
                and r + s <= iy < H2 - r - s):
            continue
        t = a[y - r:y + r + 1, x - r:x + r + 1]
        if t.std() < min_std * rng:
            continue
        if depth is not None:
            dz = depth[y - r:y + r + 1, x - r:x + r + 1]
            if not np.all(np.isfinite(dz)) or dz.max() - dz.min() > max_depth_step * dz.min():
                continue
        m = cv2.matchTemplate(b[iy - r - s:iy + r + s + 1, ix - r - s:ix + r + s + 1], t,
                              cv2.TM_CCOEFF_NORMED)
        j, i = np.unravel_index(int(np.argmax(m)), m.shape)
        if m[j, i] < min_peak or not (0 < i < m.shape[1] - 1 and 0 < j < m.shape[0] - 1):
            continue
        out[k] = (ix - s + i + _parabola(m[j, i - 1], m[j, i + 1], m[j, i]),
                  iy - s + j + _parabola(m[j - 1, i], m[j + 1, i], m[j, i]))
    return out


def focal_scale(pairs: Sequence[tuple[np.ndarray, np.ndarray]],
                robust_px: float = 0.1) -> dict:
    """The common focal-length change ``eps`` (relative) that best explains the offsets
    of several view pairs: each pair ``(offsets (n, 2), d_pred / d_eps (n, 2))`` (found
    minus predicted, px; the prediction's derivative in ``eps``), its own constant shift
    removed. Least squares, a Cauchy-weighted refit (``robust_px``) and the spread of the
    per-pair fits."""
    centred = []
    for r, D in pairs:
        ok = np.all(np.isfinite(r), axis=1)
        if ok.sum() >= 2:
            centred.append((D[ok] - D[ok].mean(axis=0), r[ok] - r[ok].mean(axis=0)))
    if not centred:
        raise ValueError("no pair has two matched patches")
    eps = sum(float((D * r).sum()) for D, r in centred) / sum(float((D * D).sum())
                                                              for D, r in centred)
    robust = eps
    for _ in range(10):
        num = den = 0.0
        for D, r in centred:
            w = 1.0 / (1.0 + ((r - robust * D) / robust_px) ** 2)
            num += float((w * D * r).sum())
            den += float((w * D * D).sum())
        robust = num / den
    per_pair = [float((D * r).sum() / (D * D).sum()) for D, r in centred
                if float((D * D).sum()) > 0]
    return {"eps_pct": 100.0 * eps, "eps_robust_pct": 100.0 * robust,
            "per_pair_median_pct": 100.0 * float(np.median(per_pair)),
            "per_pair_iqr_pct": [100.0 * float(q) for q in np.percentile(per_pair, [25, 75])],
            "pairs": len(centred), "patches": int(sum(len(r) for _, r in centred))}


def parallax_ratio(offsets: np.ndarray, shift: np.ndarray, inv_depth: np.ndarray
                   ) -> tuple[float, float]:
    """The offsets' slope in inverse depth over the predicted shift's (x and y): 0 where
    the views show the true cameras' parallax, -0.02 where they show 2 % less. ``offsets``
    (found minus predicted) and ``shift`` (predicted minus the patch's own pixel), (n, 2);
    ``inv_depth`` (n,). NaN along an axis the prediction does not move with depth, and
    where fewer than three patches, or patches at one depth only, were found."""
    ok = np.all(np.isfinite(offsets), axis=1)
    if ok.sum() < 3 or not np.ptp(inv_depth[ok]) > 0:
        return float("nan"), float("nan")
    x = inv_depth[ok] - inv_depth[ok].mean()
    span = float(np.ptp(x))
    # least-squares slopes in inverse depth (the intercepts drop out of the ratio)
    slope_pred = x @ (shift[ok] - shift[ok].mean(axis=0))
    slope_off = x @ (offsets[ok] - offsets[ok].mean(axis=0))
    scale = float(x @ x)
    # under MIN_PARALLAX_PX of parallax over the depths (a view beside the central one on
    # the other axis): nothing to compare
    out = [float(slope_off[a] / slope_pred[a])
           if abs(slope_pred[a]) / scale * span >= MIN_PARALLAX_PX else float("nan")
           for a in (0, 1)]
    return out[0], out[1]
