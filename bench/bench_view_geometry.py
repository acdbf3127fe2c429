"""The converted views' geometry against the simulator's true cameras, with no adjustment
(issue 32; plenocal.verify.view_geometry; BENCHMARKS.md, "The dense lean: where it is").

For each kept capture of ``bench_accuracy.py`` (``bench/out/accuracy/<capture>/``):

* **magnification**: each shot's central view, its true depth map and the true cameras
  predict where every textured patch of smooth depth lies in the other shots' central
  views (the pairs with a hand-held shot in them: the turns carry the magnification);
  the common focal-length change that explains the offsets (% : what a calibration of
  these views should find against the truth);
* **parallax within a set**: the same from each ``--set-stride``-th shot's central view
  into its other views; per view, the offsets' slope in inverse depth over the true
  cameras' (-0.02: the view shows 2 % less parallax than the truth's), and their median
  over the views.

Usage::

    python bench/bench_view_geometry.py dense-s15 default-s16 [--step 12] [--set-stride 3]
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import sys
from pathlib import Path

import cv2
import numpy as np
from bench_accuracy import require_kept_capture
from benchmd import positive_int

from plenocal.artifacts.cameras import read_cameras
from plenocal.io.files import read_npy
from plenocal.names import split_key
from plenocal.verify import view_geometry as vg

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out" / "accuracy"
DATASET = "synthetic"


def _grey(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH)
    if img is None:
        raise SystemExit(f"{path}: not a readable image (run bench_accuracy.py first)")
    return img.astype(np.float32)


def _grid(shape: tuple[int, int], step: int, margin: int) -> np.ndarray:
    ys, xs = np.mgrid[margin:shape[0] - margin:step, margin:shape[1] - margin:step]
    return np.column_stack([xs.ravel(), ys.ravel()]).astype(float)


def measure(capture: str, step: int, set_stride: int) -> dict:
    d = OUT / capture / "results" / DATASET
    truth = read_cameras(d / "ground_truth" / "cameras.json")
    shots = sorted({split_key(k)[0] for k in truth})
    views = sorted({split_key(k)[1] for k in truth})
    central = views[len(views) // 2]
    images: dict[tuple[str, str], np.ndarray] = {}
    depths: dict[tuple[str, str], np.ndarray] = {}

    def grey(shot: str, view: str) -> np.ndarray:
        if (shot, view) not in images:
            images[(shot, view)] = _grey(d / "views" / shot / f"{view}.png")
        return images[(shot, view)]

    def pair(s1: str, v1: str, s2: str, v2: str, deriv: bool = False):
        """The patches, their depths, predicted and found places in view 2, and (``deriv``)
        the prediction's derivative in the focal-length change."""
        c1, c2 = truth[f"{s1}/{v1}"], truth[f"{s2}/{v2}"]
        if (s1, v1) not in depths:
            depths[(s1, v1)] = read_npy(d / "ground_truth" / "depth" / s1 / f"{v1}.npy")
        depth = depths[(s1, v1)]
        img = grey(s1, v1)
        uv = _grid(img.shape, step, 16)
        z = depth[uv[:, 1].astype(int), uv[:, 0].astype(int)].astype(float)
        ok = np.isfinite(z) & (z > 0)
        uv, z = uv[ok], z[ok]
        pred = vg.predict(c1, c2, uv, z)
        found = vg.match_patches(img, grey(s2, v2), uv, pred, depth=depth)
        d_eps = (vg.predict(c1, c2, uv, z, eps=1e-4) - pred) / 1e-4 if deriv else None
        return uv, z, pred, found, d_eps

    pairs = []
    for s1, s2 in itertools.permutations(shots, 2):
        if s1.startswith("hand") or s2.startswith("hand"):
            _, _, pred, found, d_eps = pair(s1, central, s2, central, deriv=True)
            pairs.append((found - pred, d_eps))
    mag = vg.focal_scale(pairs)
    ratios: dict[str, list[tuple[float, float]]] = {v: [] for v in views if v != central}
    for s in shots[::set_stride]:
        for v in ratios:
            uv, z, pred, found, _ = pair(s, central, s, v)
            ratios[v].append(vg.parallax_ratio(found - pred, pred - uv, 1.0 / z))
    per_view = {}
    for v, rs in ratios.items():
        vals = [r for xy in rs for r in xy if np.isfinite(r)]
        per_view[v] = statistics.median(vals) if vals else float("nan")
    return {"magnification": mag, "parallax_per_view": per_view,
            "parallax_median": statistics.median(x for x in per_view.values()
                                                 if np.isfinite(x))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("captures", nargs="+", help="kept captures, e.g. dense-s15")
    ap.add_argument("--step", type=int, default=12, help="patch grid step (px)")
    ap.add_argument("--set-stride", type=positive_int, default=3,
                    help="every k-th shot's set measured for the parallax within a set")
    args = ap.parse_args()
    for cap in args.captures:
        require_kept_capture(OUT / cap)
    print("| capture | focal change the views show, LS / robust % | per-pair median % "
          "(interquartile) | pairs / patches | parallax within a set, median over views |")
    print("|---|---|---|---|---|")
    for cap in args.captures:
        r = measure(cap, args.step, args.set_stride)
        m = r["magnification"]
        print(f"| {cap} | {m['eps_pct']:+.3f} / {m['eps_robust_pct']:+.3f} | "
              f"{m['per_pair_median_pct']:+.3f} ({m['per_pair_iqr_pct'][0]:+.3f} to "
              f"{m['per_pair_iqr_pct'][1]:+.3f}) | {m['pairs']} / {m['patches']} | "
              f"{100 * r['parallax_median']:+.1f} % |", flush=True)
        print("  per view: " + ", ".join(f"{v} {100 * x:+.1f}"
                                         for v, x in r["parallax_per_view"].items()),
              file=sys.stderr)


if __name__ == "__main__":
    main()
