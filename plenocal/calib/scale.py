"""The scale between registration A (SfM units) and registration B (metres): Eq. 5.

For the central view of shot i, ``d1`` is its depth map computed with registration A
and ``d2`` with registration B (z-depth, 0 = invalid). A pixel is valid in a map
when its depth is positive, finite and within the [low, high] percentile of that
map's valid depths (the paper keeps the 2nd to 9th deciles: 10th-90th percentile).
Eq. 5::

    r_i = mean over valid(d1) AND valid(d2) of d2 / d1

and ``r = mean_i r_i``. Because the paper's mean is sensitive to a shot whose depth
failed, a robust estimate is reported beside it: the median of r_i, and the
per-shot median of the ratios; the spread (std, min, max, relative spread) of r_i
says how far the shots agree.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from plenocal.artifacts.scale import ScaleResult
from plenocal.config import stage_defaults
from plenocal.io.files import read_npy
from plenocal.names import array_position

_SCALE = stage_defaults("scale")  # the defaults below: config.schema.yaml's scale block
_LOW, _HIGH = float(_SCALE["low_percentile"]), float(_SCALE["high_percentile"])


def valid_mask(depth: np.ndarray, low: float = _LOW, high: float = _HIGH) -> np.ndarray:
    """Pixels > 0, finite and within the [low, high] percentile of the map's valid depths."""
    d = np.asarray(depth, dtype=np.float64)
    ok = np.isfinite(d) & (d > 0)
    if not ok.any():
        return ok
    lo, hi = np.percentile(d[ok], [low, high])
    return ok & (d >= lo) & (d <= hi)


def shot_ratio(d1: np.ndarray, d2: np.ndarray, low: float = _LOW, high: float = _HIGH,
               name: str = "") -> dict:
    """Eq. 5 for one shot: r_i (mean of d2/d1), n pixels, and the median of the ratios."""
    d1 = np.asarray(d1)
    d2 = np.asarray(d2)
    if d1.shape != d2.shape:
        raise ValueError(f"{name}: depth maps of registrations A and B differ in size "
                         f"({d1.shape} vs {d2.shape}); both must be of the central view, made "
                         "with one depth.registration_downsample: rerun the depth stage "
                         "(snakemake --forcerun depth)")
    m = valid_mask(d1, low, high) & valid_mask(d2, low, high)
    n = int(m.sum())
    if n == 0:
        raise ValueError(f"{name}: no pixel is valid in both depth maps (A and B); check the "
                         "depth stage's output for this shot (its preview PNGs); on small "
                         "views, depth.registration_downsample: 1 makes them at full size")
    ratio = d2[m].astype(np.float64) / d1[m].astype(np.float64)
    return {"r": float(ratio.mean()), "median": float(np.median(ratio)), "n": n,
            "std": float(ratio.std())}


def combine(ratios: Mapping[str, dict]) -> dict:
    """r = mean_i r_i (the paper), the robust estimates and the spread across shots."""
    if not ratios:
        raise ValueError("no shot to compute the scale from")
    names = sorted(ratios)
    r_i = np.array([ratios[k]["r"] for k in names])
    med_i = np.array([ratios[k]["median"] for k in names])
    r = float(r_i.mean())
    return {
        "r_i": {k: ratios[k]["r"] for k in names},
        "r_i_median_of_ratios": {k: ratios[k]["median"] for k in names},
        "n_pixels": {k: ratios[k]["n"] for k in names},
        "r": r,
        "r_median": float(np.median(r_i)),
        "r_median_of_ratios": float(np.median(med_i)),
        "spread": {"std": float(r_i.std(ddof=1)) if len(r_i) > 1 else 0.0,
                   "min": float(r_i.min()), "max": float(r_i.max()),
                   "relative": float((r_i.max() - r_i.min()) / r) if r else None,
                   "n_shots": len(names)},
    }


def load_depth(path: str | Path) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: depth map not found; run the depth rule first")
    d = read_npy(path)
    if d.ndim != 2:
        raise ValueError(f"{path}: a depth map must be 2-D (got shape {d.shape})")
    return d


def array_step_scale(poses: Mapping[str, np.ndarray], step_m: float) -> dict | None:
    """The scale (metres per SfM unit) that the stage's step gives: registration A's array
    shots (``x<col>_y<row>``: ``poses``, camera-to-world, SfM units; hand-held shots are
    skipped) fitted by a lattice ``centre = o + col a + row b`` (least squares), its
    spacing ``|a|``, ``|b|`` averaged with the weight of each axis's leverage (the sum
    of squared index deviations), and ``step_m`` over it. None where the array has one
    shot. The fit's residual says how regular A found the array."""
    grid = {array_position(s): np.asarray(M, dtype=float)[:3, 3] for s, M in poses.items()
            if array_position(s) is not None}
    if len(grid) < 2:
        return None
    keys = sorted(grid)
    idx = np.array(keys, dtype=float)
    P = np.array([grid[k] for k in keys])
    lever = ((idx - idx.mean(axis=0)) ** 2).sum(axis=0)  # per axis (col, row)
    use = [a for a in (0, 1) if lever[a] > 0]
    X = np.column_stack([idx[:, use], np.ones(len(keys))])
    coef, *_ = np.linalg.lstsq(X, P, rcond=None)
    steps = {("col", "row")[a]: float(np.linalg.norm(coef[i])) for i, a in enumerate(use)}
    spacing = sum(lever[a] * steps[("col", "row")[a]] for a in use) / sum(lever[a] for a in use)
    residual = P - X @ coef
    return {"r": float(step_m) / spacing, "step_m": float(step_m),
            "spacing_sfm": float(spacing), "spacing_sfm_per_axis": steps,
            "n_shots": len(keys),
            "fit_rms_pct_of_step": 100.0 * float(np.sqrt((residual ** 2).sum(axis=1).mean()))
            / spacing}


#: Eq. 5's r and the stage's step disagreeing by more than this (relative) is a warning
AGREEMENT = 0.02


def estimate_scale(pairs: Mapping[str, tuple[str | Path, str | Path]], low: float = _LOW,
                   high: float = _HIGH, estimator: str = _SCALE["estimator"],
                   log=None, reference: str = _SCALE["reference"],
                   array_poses: Mapping[str, np.ndarray] | None = None,
                   step_m: float | None = None) -> ScaleResult:
    """Eq. 5 from the depth files (:func:`scale_from_files`) as the typed result that
    ``scale.json`` holds, ``estimator`` naming Eq. 5's r; with registration A's poses
    (``array_poses``) and the stage's step (``step_m``), the scale the step gives beside
    it (:func:`array_step_scale`). ``reference``: which the merge uses - ``eq5``,
    ``array_step``, or ``auto``: the step where it is known, Eq. 5 otherwise."""
    out = scale_from_files(pairs, low, high, log=log)
    step = (array_step_scale(array_poses, step_m) if array_poses is not None and step_m
            else None)
    if reference == "array_step" and step is None:
        raise ValueError("config scale.reference = array_step needs the stage's step "
                         "(camera.yaml: array.step_mm) and two or more array shots; use "
                         "scale.reference: auto or eq5")
    chosen = ("array_step" if step is not None and reference in ("array_step", "auto")
              else "eq5")
    eq5 = {"mean": out["r"], "median": out["r_median"],
           "median_of_ratios": out["r_median_of_ratios"]}[estimator]
    warnings = []
    if step is not None and abs(step["r"] / eq5 - 1.0) > AGREEMENT:
        warnings.append(f"the scale of Eq. 5 (r = {eq5:.6g}) and the stage's step "
                        f"({1000 * step['step_m']:g} mm in camera.yaml: r = {step['r']:.6g}) "
                        f"differ by {100 * (step['r'] / eq5 - 1.0):+.2f} %; the merge uses "
                        f"{'the step' if chosen == 'array_step' else 'Eq. 5'}: check "
                        "array.step_mm, or the depth maps of both registrations")
    return ScaleResult(
        r=out["r"], r_median=out["r_median"], r_median_of_ratios=out["r_median_of_ratios"],
        estimator=estimator, r_i=out["r_i"], r_i_median_of_ratios=out["r_i_median_of_ratios"],
        n_pixels=out["n_pixels"], spread=out["spread"], percentiles=(low, high),
        method=out["method"], chosen=chosen,
        r_array_step=None if step is None else step["r"],
        array_step=step or {}, warnings=tuple(warnings))


def scale_from_files(pairs: Mapping[str, tuple[str | Path, str | Path]], low: float = _LOW,
                     high: float = _HIGH, log=None) -> dict:
    """``pairs``: shot -> (depth of registration A, depth of registration B)."""
    ratios = {}
    for cam in sorted(pairs):
        a, b = pairs[cam]
        ratios[cam] = shot_ratio(load_depth(a), load_depth(b), low, high, name=cam)
        if log is not None:
            log(f"{cam}: r_i = {ratios[cam]['r']:.6g} over {ratios[cam]['n']} pixels")
    out = combine(ratios)
    out.update(method="Eq. 5: mean of d_B/d_A over pixels valid in both maps",
               percentiles=[low, high])
    return out
