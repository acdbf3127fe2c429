"""Where the refined focal length's lean comes from (issue 32): the same refinement on the
keypoints of our views and on those of the simulator's ideal pinhole renders.

The refined focal length leans positive on the default geometry (ten captures of ten
above the truth). ``bench_focal_information.py`` found that the observations' small
systematic errors set it, not the solver. This bench asks whose errors they are. For
each kept capture of ``bench_accuracy.py`` (``bench/out/accuracy/<capture>``):

1. every view of every shot is rendered as the ideal pinhole camera the truth says it is
   (``plenocal.simulate.groundtruth.render_views``, as rule ``ground_truth_render``;
   cached under ``--renders``), with its z-depth;
2. the same SIFT as the view database (:func:`plenocal.calib.reg_a.colmap.opencv_sift`)
   runs on each render, and each of the refinement's observations is paired with the
   render's keypoint nearest to it (within ``--within`` px, the SIFT scales' ratio within
   0.82-1.22: ``|log ratio| < 0.2``);
3. the refinement (the workflow's settings, Eq. 6's cameras as its start) runs on the
   paired observations only, five times:

   * ``ours``: at our keypoints;
   * ``true renders``: at the renders' keypoints (the same tracks: only the places move);
   * ``true + low order``: at the renders' keypoints plus, per view, the least-squares
     fit of our offsets from them by a shift, a term in 1 / Z per axis (a view centre off
     the truth's: parallax) and the four linear terms of the position (a magnification or
     shear), so that our views' low-order errors come back and their rest does not;
   * ``true + low order + radial``: the same fit with a radial term, ``k (r / 300)^2``
     times the offset from the principal point (a barrel or pincushion distortion of the
     view against the truth's pinhole);
   * ``true + low order + depth scale``: the low-order fit with a magnification that
     changes with depth instead, ``m (1 / Z - mean 1 / Z)`` times the offset from the
     principal point (a pinhole's magnification does not).

Also reported per capture: the median over the views of the radial term (px at 300 px
from the principal point; negative: barrel) and of the depth scale term (the same, per
1 / m), and the range over the 25 view positions of their mean 1 / Z terms (px at
1 / Z = 1 per metre; a uniform spread is a baseline scale, which the refinement's
``scale_pp`` rig absorbs).

Usage::

    python bench/bench_feature_truth.py [--captures default-s8 default-s3 wide-s3]
        [--within 0.8] [--out BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_accuracy import require_kept_capture  # noqa: E402
from bench_focal_information import OUT, _rebuilt, kept_capture, refine_runs  # noqa: E402
from benchmd import Lines, update_sections  # noqa: E402

from plenocal.artifacts.cameras import read_cameras  # noqa: E402
from plenocal.calib.reg_a.colmap import opencv_sift  # noqa: E402
from plenocal.io.files import read_json, read_npy  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RENDERS = ROOT / "bench" / "out" / "feature_truth"
SECTION = "Whose errors lean the focal length: our views' keypoints or SIFT's (issue 32)"
RUNS = ("ours", "true renders", "true + low order", "true + low order + radial",
        "true + low order + depth scale")
#: the extra column of each fitted run (:func:`design`)
EXTRA = {"true + low order": None, "true + low order + radial": "radial",
         "true + low order + depth scale": "depth"}
SCALE_TOL = 0.2  # |log(scale ratio)| of a pair


def render_truth(capture: Path, dest: Path, supersample: int) -> None:
    """Every view of every shot of ``capture`` as the truth's pinhole camera (image and
    z-depth, ``supersample`` rays per pixel and axis), those not yet in ``dest``."""
    from plenocal.simulate.groundtruth import render_views  # noqa: PLC0415

    res = capture / "results" / "synthetic"
    truth = read_cameras(res / "ground_truth" / "cameras.json")
    keys = sorted(k for k in truth if not (dest / f"{_flat(k)}.npy").exists())
    if not keys:
        return
    dest.mkdir(parents=True, exist_ok=True)
    print(f"{capture.name}: rendering {len(keys)} true views into {dest}", flush=True)
    render_views(capture / "data" / "synthetic" / "truth" / "scene.json",
                 res / "ground_truth" / "cameras.json", keys, supersample,
                 [dest / f"{_flat(k)}.png" for k in keys],
                 [dest / f"{_flat(k)}.npy" for k in keys], log=lambda _m: None)


def _flat(key: str) -> str:
    return key.replace("/", "_")


def view_fit(ours: np.ndarray, true: np.ndarray, centre: np.ndarray, z: np.ndarray,
             good: np.ndarray, extra: str | None) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares fit (:func:`design`) of the offsets ``ours - true`` (px) over
    ``good``: its coefficients and the fitted offsets at every keypoint, (n, 2)."""
    A = design(true, centre, z, good, extra)
    rows = np.repeat(good, 2)
    coef = np.linalg.lstsq(A[rows], (ours - true).ravel()[rows], rcond=None)[0]
    return coef, (A @ coef).reshape(-1, 2)


def design(true: np.ndarray, centre: np.ndarray, z: np.ndarray, good: np.ndarray,
           extra: str | None) -> np.ndarray:
    """(2n, 8 or 9) design of the offsets (x and y rows interleaved) at the keypoints
    ``true``: per axis a shift, 1 / Z (Z in m; Z <= 0: 0), x / 300 and y / 300 (from
    ``centre``); ``extra`` one more column shared by both axes, the position over 300 px
    times ``(r / 300)^2`` (``"radial"``) or times ``1 / Z`` less its mean over ``good``
    (``"depth"``)."""
    p = (true - centre) / 300.0
    iz = np.where(z > 0, 1.0 / np.maximum(z, 1e-9), 0.0)
    one = np.ones(len(true))
    block = np.column_stack([one, iz, p[:, 0], p[:, 1]])
    A = np.zeros((2 * len(true), 8 if extra is None else 9))
    A[0::2, 0:4] = block
    A[1::2, 4:8] = block
    if extra is not None:
        w = ((p ** 2).sum(axis=1) if extra == "radial" else iz - iz[good].mean())
        A[0::2, 8] = p[:, 0] * w
        A[1::2, 8] = p[:, 1] * w
    return A


def pair_observations(tracks, point_ids: list[int], database_kp: dict, renders: Path,
                      truth: dict, within: float) -> dict:
    """The refinement's observations paired with the true renders' keypoints: ``keep``
    (the paired (image_id, point2D_idx)), ``places`` (run -> their places), ``depth``
    (view -> each image's (1 / Z term x, y) of the low-order fit), ``terms`` (extra ->
    each image's extra term, px at 300 px) and ``n`` (the observations)."""
    per_image: dict[int, set] = {}
    for pid in point_ids:
        for e in tracks.point3D(pid).track.elements:
            per_image.setdefault(e.image_id, set()).add(e.point2D_idx)
    keep, depth_terms, terms = set(), {}, {"radial": [], "depth": []}
    places: dict[str, dict] = {run: {} for run in RUNS[1:]}
    n = 0
    for iid in sorted(per_image):
        name = tracks.image(iid).name
        key = name[:-4]
        idx = np.array(sorted(per_image[iid]))
        n += len(idx)
        kp = database_kp[name][idx]
        grey = cv2.imread(str(renders / f"{_flat(key)}.png"), cv2.IMREAD_GRAYSCALE)
        depth = read_npy(renders / f"{_flat(key)}.npy")
        tk = opencv_sift(grey, 8192)[0].astype(np.float64)
        nn = cv2.flann_Index(tk[:, :2].astype(np.float32), {"algorithm": 1, "trees": 4})
        j, d2 = nn.knnSearch(kp[:, :2].astype(np.float32), 1, params={"checks": 64})
        j = j[:, 0]
        ok = ((np.sqrt(d2[:, 0]) < within)
              & (np.abs(np.log(kp[:, 2] / tk[j, 2])) < SCALE_TOL))
        t = tk[j, :2]
        xi = np.clip(np.round(t[:, 0] - 0.5).astype(int), 0, depth.shape[1] - 1)
        yi = np.clip(np.round(t[:, 1] - 0.5).astype(int), 0, depth.shape[0] - 1)
        z = depth[yi, xi]
        cam = truth[key]
        centre = np.array([cam.K[0, 2] + 0.5, cam.K[1, 2] + 0.5])  # COLMAP's pixel convention
        ours = kp[:, :2].astype(np.float64)
        good = ok & (z > 0) & (np.hypot(*(ours - t).T) < 0.6)
        moved = {"true renders": t}
        for run, extra in EXTRA.items():
            coef, fitted = view_fit(ours, t, centre, z, good, extra)
            moved[run] = t + fitted
            if extra is None:
                depth_terms.setdefault(key.split("/")[1], []).append((coef[1], coef[5]))
            else:
                terms[extra].append(float(coef[8]))
        for m in np.flatnonzero(ok):
            k = (iid, int(idx[m]))
            keep.add(k)
            for run, xy in moved.items():
                places[run][k] = xy[m]
    return {"keep": keep, "places": places, "depth": depth_terms, "terms": terms, "n": n}


def run(capture: str, within: float, renders_root: Path) -> dict:
    import pycolmap  # noqa: PLC0415

    cap = kept_capture(capture)
    renders = renders_root / capture
    render_truth(OUT / capture, renders,
                 int(cap.cfg["datasets"]["synthetic"]["simulate"]["render"]["ideal_supersample"]))
    with pycolmap.Database.open(str(cap.res / "matches" / "database.db")) as db:
        database_kp = {im.name: db.read_keypoints(im.image_id) for im in db.read_all_images()}
    state: dict = {}

    def rebuild(how: str, rec, tracks, point_ids):
        if "pairs" not in state:
            state["pairs"] = pair_observations(tracks, point_ids, database_kp, renders,
                                               cap.truth, within)
        pairs = state["pairs"]
        xy = pairs["places"].get(how, {})  # "ours": the keypoints as they are
        return _rebuilt(rec, xy, pairs["keep"], point_ids, tracks)

    out = refine_runs(cap, list(RUNS), rebuild)
    pairs = state["pairs"]
    out["paired"] = (len(pairs["keep"]), pairs["n"])
    depth = np.array([np.mean(pairs["depth"][v], axis=0) for v in sorted(pairs["depth"])])
    out["depth_range"] = (float(np.ptp(depth[:, 0])), float(np.ptp(depth[:, 1])))
    out["terms"] = {k: float(np.median(v)) for k, v in pairs["terms"].items()}
    out["workflow"] = _workflow_focal(cap.res)
    return out


def _workflow_focal(res: Path) -> float:
    gt = read_json(res / "eval" / "gt_errors.json")
    return float(gt["complete"]["focal_err_signed_pct"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--captures", nargs="+", default=["default-s8", "default-s3", "wide-s3"])
    ap.add_argument("--within", type=float, default=0.8,
                    help="largest distance (px) of a pair of keypoints")
    ap.add_argument("--renders", type=Path, default=RENDERS,
                    help="cache of the true renders, one folder per capture")
    ap.add_argument("--out", help="write the section into this Markdown file")
    args = ap.parse_args()
    for capture in args.captures:
        require_kept_capture(OUT / capture)
    results = {c: run(c, args.within, args.renders) for c in args.captures}

    lines = Lines()
    lines.say(f"`python bench/bench_feature_truth.py --captures {' '.join(args.captures)}` on "
              "the kept captures of `bench_accuracy.py`. The refined focal length's signed "
              "error (%) on the refinement's observations that pair with a keypoint of the "
              f"true render within {args.within} px (the SIFT scales' ratio within "
              f"{math.exp(-SCALE_TOL):.2f}-{math.exp(SCALE_TOL):.2f}: |log ratio| < "
              f"{SCALE_TOL}), and the "
              "refinement's median reprojection error after it (px):")
    lines.say("")
    lines.head("capture", "the workflow (all observations)", "paired observations",
               *[f"{r} (median px)" for r in RUNS], "radial term px at 300 px",
               "depth scale term px at 300 px per 1 / m",
               "1 / Z terms' range over the views, x / y px")
    for c, o in results.items():
        kept, n = o["paired"]
        lines.say(f"| {c} | {o['workflow']:+.3f} | {kept} of {n} | "
                  + " | ".join(f"{o['runs'][r]:+.3f} ({o['median'][r]:.3f})" for r in RUNS)
                  + f" | {o['terms']['radial']:+.4f} | {o['terms']['depth']:+.4f} | "
                  f"{o['depth_range'][0]:.3f} / "
                  f"{o['depth_range'][1]:.3f} |")
    if args.out:
        update_sections(args.out, {SECTION: lines})


if __name__ == "__main__":
    main()
