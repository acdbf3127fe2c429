"""Are the central views pinhole views? Their scale against the truth, and its change with
depth (issue 32: where registration A's focal error comes from).

For each capture kept by ``bench/bench_accuracy.py`` (``bench/out/accuracy/<capture>``), each
shot's central view is compared with the simulator's ideal pinhole render of the same
true camera (``ground_truth/renders``): dense optical flow (OpenCV's DIS) from the render
to our view over the render's textured pixels away from depth edges, then per view the
least-squares fit

    p_ours - c = (1 + s + k / Z) (p_true - c) + t

with Z the true depth of the pixel (m) and c the image centre. A focal length off by e %
in our views would read as s = e %; a magnification that changes with depth, which
structure-from-motion could trade against the focal length, as k. Reported per capture:
the median over its views of s and of the near - far magnification difference
k (1 / Z_10 - 1 / Z_90) (the 10th and 90th percentiles of the view's depth), in per cent,
beside registration A's focal error from the capture's gt_errors.json.

Usage::

    python bench/bench_central_scale.py [--captures default-s1 wide-s2 ...]
        [--out BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
from bench_accuracy import require_kept_capture
from benchmd import Lines, update_sections

from plenocal.io.files import read_json, read_npy

ROOT = Path(__file__).resolve().parent / "out" / "accuracy"
SECTION = "Central views against the true pinhole renders (issue 32)"


def flow_field(true: np.ndarray, ours: np.ndarray) -> np.ndarray:
    """(H, W, 2) flow with ``true(p) ~ ours(p + flow(p))`` (grey uint8 images)."""
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
    dis.setFinestScale(0)
    dis.setPatchSize(12)
    dis.setPatchStride(3)
    dis.setGradientDescentIterations(25)
    return dis.calc(true, ours, None).astype(np.float64)


def usable(true: np.ndarray, depth: np.ndarray, border: int = 16) -> np.ndarray:
    """Pixels with texture in ``true``, a valid depth, away from depth edges and the border."""
    g = true.astype(np.float32)
    gx, gy = cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1)
    ok = cv2.GaussianBlur(gx * gx + gy * gy, (0, 0), 3) > 200
    valid = np.isfinite(depth) & (depth > 0)
    logz = np.log(np.where(valid, depth, 1.0)).astype(np.float32)
    edge = (np.abs(cv2.Sobel(logz, cv2.CV_32F, 1, 0))
            + np.abs(cv2.Sobel(logz, cv2.CV_32F, 0, 1))) > 0.02
    edge = cv2.dilate(edge.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    ok &= valid & ~edge
    ok[:border] = ok[-border:] = False
    ok[:, :border] = ok[:, -border:] = False
    return ok


def fit_scale(flow: np.ndarray, depth: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(s, k) of ``p + flow - c = (1 + s + k / Z) (p - c) + t`` by least squares, refitted
    without the residuals above three times their median (flow outliers)."""
    h, w = mask.shape
    yy, xx = np.nonzero(mask)
    x, y = xx - (w - 1) / 2.0, yy - (h - 1) / 2.0
    iz = 1.0 / depth[mask]
    n = len(x)
    a = np.zeros((2 * n, 4))
    a[:n, 0] = 1.0
    a[n:, 1] = 1.0
    a[:n, 2], a[n:, 2] = x, y
    a[:n, 3], a[n:, 3] = x * iz, y * iz
    b = np.concatenate([flow[..., 0][mask], flow[..., 1][mask]])
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    res = np.abs(b - a @ sol)
    keep = res < 3.0 * np.median(res) + 0.05
    sol = np.linalg.lstsq(a[keep], b[keep], rcond=None)[0]
    return float(sol[2]), float(sol[3])


def capture_figures(folder: Path, central: str = "2_2") -> dict:
    """Median s and near - far magnification (per cent) over the capture's central views."""
    res = folder / "results" / "synthetic"
    s_all, dm_all = [], []
    for shot in sorted(p.name for p in (res / "ground_truth" / "renders").iterdir()):
        true = cv2.imread(str(res / "ground_truth" / "renders" / shot / f"{central}.png"),
                          cv2.IMREAD_GRAYSCALE)
        ours = cv2.imread(str(res / "views" / shot / f"{central}.png"), cv2.IMREAD_GRAYSCALE)
        if true is None or ours is None or true.shape != ours.shape:
            raise SystemExit(f"{folder}: {shot}/{central}: the render and our view are "
                             "missing or of different sizes (run bench_accuracy.py first)")
        depth = read_npy(res / "ground_truth" / "depth" / shot / f"{central}.npy")
        mask = usable(true, depth.astype(np.float64))
        s, k = fit_scale(flow_field(true, ours), depth.astype(np.float64), mask)
        z10, z90 = np.percentile(depth[mask], [10.0, 90.0])
        s_all.append(100.0 * s)
        dm_all.append(100.0 * k * (1.0 / z10 - 1.0 / z90))
    gt = read_json(res / "eval" / "gt_errors.json")
    return {"views": len(s_all), "s": float(np.median(s_all)),
            "near_far": float(np.median(dm_all)),
            "a_focal": gt.get("sources", {}).get("a_focal_pct")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--captures", nargs="*", default=None,
                    help="capture folders under bench/out/accuracy (default: all)")
    ap.add_argument("--out", default=None, help="BENCHMARKS.md to update (its section)")
    args = ap.parse_args()
    names = args.captures or sorted(p.name for p in (ROOT.iterdir() if ROOT.is_dir() else ())
                                    if (p / "results").is_dir() and "-refine" not in p.name)
    if not names:
        raise SystemExit(f"no kept captures in {ROOT}: run bench/bench_accuracy.py first")
    for name in names:
        require_kept_capture(ROOT / name)
    lines = Lines()
    lines.say("Each capture's central views (one per shot) against the simulator's ideal "
              "pinhole renders of the same true cameras (bench/bench_central_scale.py): "
              "dense flow, then per view `p_ours - c = (1 + s + k / Z) (p_true - c) + t`; "
              "medians over the views, per cent. A focal error in our views would read "
              "as s; a magnification that changes with depth as the near - far column "
              "(k over the 10th-90th percentiles of the view's depth).")
    lines.say("")
    lines.head("capture", "views", "s %", "near - far %", "registration A's focal error %")
    for name in names:
        f = capture_figures(ROOT / name)
        a = "-" if f["a_focal"] is None else f"{f['a_focal']:+.3f}"
        lines.say(f"| {name} | {f['views']} | {f['s']:+.3f} | {f['near_far']:+.3f} | {a} |")
    if args.out:
        update_sections(args.out, {SECTION: lines})


if __name__ == "__main__":
    main()
