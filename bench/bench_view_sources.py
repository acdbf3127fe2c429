"""Where the refined focal length's error comes from: the converted views against the
simulator's ideal pinhole renders of the same cameras (issue 32).

For each kept capture of ``bench_accuracy.py`` (``bench/out/accuracy/<capture>/``), a copy
of it (``bench/out/view_sources/<capture>-<kind>/``) has every subaperture view replaced,
and the chain from the views on runs again as the workflow runs it (:func:`view_rules`):
SIFT of every view (rules ``view_features_<k>``) and the view matches, the central views'
own matches (rule ``match_central``, for ``refine.tracks: both``, the default, and
``central``), the
joint refinement, the errors against the truth. Registration A, B, the depth maps, Eq. 5
and Eq. 6 stay the kept capture's (on the converted views): only what the refinement
observes changes. The kinds:

* ``ideal``: the simulator's ideal pinhole render of each view's true camera
  (:func:`plenocal.simulate.groundtruth.render_views`, the config's
  ``render.ideal_supersample``), the views' size;
* ``blur``: the ideal render blurred by a Gaussian whose sigma is fitted, per capture, so
  that the held shot's central view is closest to the converted one (grey levels, after
  a gain and offset; :func:`fitted_softness`);
* ``noise``: ``blur`` plus white Gaussian noise of the converted view's own residual in
  its flattest fifth (where the fit leaves noise, not structure), drawn per view from a
  fixed seed;
* ``oracle``: the converted views again, rendered with each lens's patch size taken from
  the truth (the true depth at its tile centre in the central view, through the true
  cameras' disparity between the central view and its right neighbour: ``P = s q T / D``,
  disparity.json's convention), everything else the converter's.

The kept capture's own figures (``ours``) head each capture's rows. Prints a Markdown
table: the complete calibration's signed focal error, centres RMSE, largest rotation,
and the refinement's median observation error after it.

Usage::

    python bench/bench_view_sources.py small-s27 small-s24 [--kinds ideal blur noise oracle]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import sys
import time
import zlib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import cv2
import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_accuracy import (  # noqa: E402
    DATASET,
    OUT,
    clone_capture,
    require_kept_capture,
    run_capture,
)
from benchmd import Lines  # noqa: E402

from plenocal.artifacts.cameras import read_cameras  # noqa: E402
from plenocal.config import validate_config  # noqa: E402
from plenocal.convert.viewset import read_view_set, view_set_files  # noqa: E402
from plenocal.io.files import read_json, read_npy  # noqa: E402
from plenocal.names import central_view, view_key  # noqa: E402
from plenocal.simulate.groundtruth import render_views  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / "bench" / "out" / "view_sources"
KINDS = ("ideal", "blur", "noise", "oracle")
FLAT_SHARE = 0.2  # the flattest share of a view whose residual is taken as its noise
MARGIN = 30  # px left out at a view's border by the softness fit


def view_files(res: Path) -> dict[str, Path]:
    """``<shot>/<view>`` -> the PNG of every view of a capture's results folder."""
    return view_set_files(sorted(res.glob("views/*/views.json")))


def held_central(res: Path) -> str:
    """The key of the held shot's central view (the shot the refinement holds)."""
    refine = read_json(res / "calibration" / "refine.json")
    n = int(round(len({key.split("/")[1] for key in view_files(res)}) ** 0.5))
    return view_key(refine["hold_shot"], central_view(n))


def _grey(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise OSError(f"{path}: not a readable image")
    return img.astype(np.float32)


def fitted_softness(ours: np.ndarray, ideal: np.ndarray) -> tuple[float, float]:
    """(sigma px, noise grey levels): the Gaussian blur of ``ideal`` (0.0-2.0 px in steps
    of 0.05) that, after a least-squares gain and offset, leaves the smallest rms
    difference to ``ours``; and the rms of that difference over the flattest
    :data:`FLAT_SHARE` of the blurred ideal view (its gradient)."""
    inner = (slice(MARGIN, -MARGIN), slice(MARGIN, -MARGIN))
    y = ours[inner].ravel()
    best = (np.inf, 0.0, None)
    for sigma in np.arange(0.0, 2.0001, 0.05):
        b = cv2.GaussianBlur(ideal, (0, 0), float(sigma)) if sigma > 0 else ideal
        A = np.c_[b[inner].ravel(), np.ones(y.size, np.float32)]
        coef = np.linalg.lstsq(A, y, rcond=None)[0]
        err = float(np.sqrt(np.mean((A @ coef - y) ** 2)))
        if err < best[0]:
            best = (err, float(sigma), (b, coef))
    _, sigma, (b, coef) = best
    resid = ours - (coef[0] * b + coef[1])
    grad = np.hypot(cv2.Sobel(b, cv2.CV_32F, 1, 0), cv2.Sobel(b, cv2.CV_32F, 0, 1))[inner]
    flat = grad <= np.quantile(grad, FLAT_SHARE)
    return sigma, float(resid[inner][flat].std())


def _render_part(args) -> int:
    """Ideal renders of ``keys`` written over ``files`` (their times kept), blurred by
    ``sigma`` and given noise ``noise`` where these are above 0."""
    scene, cams, supersample, keys, files, sigma, noise = args
    tmp = [f"{f}.ideal.png" for f in files]
    depth = [f"{f}.ideal.npy" for f in files]
    render_views(scene, cams, list(keys), supersample, tmp, depth, log=lambda *a: None)
    for key, f, t, d in zip(keys, files, tmp, depth, strict=True):
        if sigma > 0 or noise > 0:
            img = cv2.imread(t, cv2.IMREAD_UNCHANGED).astype(np.float32)
            if sigma > 0:
                img = cv2.GaussianBlur(img, (0, 0), sigma)
            if noise > 0:
                rng = np.random.default_rng(zlib.crc32(key.encode()))
                img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
            cv2.imwrite(t, np.clip(np.rint(img), 0, 255).astype(np.uint8))
        st = os.stat(f)
        os.replace(t, f)
        os.unlink(d)
        os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    return len(keys)


def replace_by_renders(work: Path, cfg: dict, sigma: float = 0.0, noise: float = 0.0,
                       jobs: int = 2) -> None:
    """Every view of the copy ``work`` replaced by its ideal render (module docstring)."""
    res, data = work / "results" / DATASET, work / "data" / DATASET
    files = view_files(res)
    supersample = int(cfg["datasets"][DATASET]["simulate"]["render"]["ideal_supersample"])
    items = sorted(files.items())
    parts = [items[i::jobs] for i in range(jobs)]
    args = [(str(data / "truth" / "scene.json"), str(res / "ground_truth" / "cameras.json"),
             supersample, [k for k, _ in p], [str(f) for _, f in p], sigma, noise)
            for p in parts if p]
    with ProcessPoolExecutor(len(args)) as ex:
        list(ex.map(_render_part, args))


def oracle_patch(layout, centre_depth: np.ndarray, cam, right) -> np.ndarray:
    """(m,) patch size per used lens of ``layout`` from the truth: the true depth at the
    lens's tile centre in the central view (``centre_depth``, z in the camera ``cam``),
    that point projected into the right neighbour's true camera ``right``; its disparity
    D = x - x_right gives ``P = sign q T / D`` (disparity.json's convention). NaN where
    the depth map has no surface."""
    xy = layout.tile_centres.astype(float)
    xi = np.clip(np.rint(xy[:, 0]).astype(int), 0, layout.width - 1)
    yi = np.clip(np.rint(xy[:, 1]).astype(int), 0, layout.height - 1)
    z = centre_depth[yi, xi].astype(float)
    uv, _ = right.project(cam.unproject(xy, z))  # no surface (z = 0): the centre, any x
    with np.errstate(divide="ignore", invalid="ignore"):
        patch = layout.sign * layout.q * layout.tile / (xy[:, 0] - uv[:, 0])
    return np.where((z > 0) & np.isfinite(patch) & (patch > 0), patch, np.nan)


def true_depth_maps(work: Path, cfg: dict) -> None:
    """The true depth of every shot's central view (rule ``ground_truth_render``), made in
    the copy ``work`` where the capture lacks them (a capture made with ``--no-exp1``
    rendered none)."""
    res = work / "results" / DATASET
    wanted = []
    for vs in sorted(res.glob("views/*/views.json")):
        n = int(round(len(read_view_set(vs)) ** 0.5))
        rel = f"ground_truth/depth/{vs.parent.name}/{central_view(n)}.npy"
        if not (res / rel).is_file():
            wanted.append(rel)
    if wanted:
        run_capture(work, cfg, [], 2, targets=tuple(wanted))


def rerender_with_oracle(work: Path, cfg: dict) -> list[float]:
    """Every view of the copy ``work`` rendered again with the truth's patch sizes
    (:func:`oracle_patch`); returns each shot's median |estimated / true - 1| (%)."""
    from plenocal.convert import ConvertSettings, convert_files  # noqa: PLC0415
    from plenocal.convert.analysis import read_analysis  # noqa: PLC0415
    from plenocal.io.files import write_images  # noqa: PLC0415

    res, data = work / "results" / DATASET, work / "data" / DATASET
    settings = ConvertSettings.from_config(cfg["convert"])
    truth = read_cameras(res / "ground_truth" / "cameras.json")
    errors = []
    for vs in sorted(res.glob("views/*/views.json")):
        shot = vs.parent.name
        files = read_view_set(vs)
        n = int(round(len(files) ** 0.5))
        centre, right = f"{n // 2}_{n // 2}", f"{n // 2}_{n // 2 + 1}"
        analysis = read_analysis(vs.parent / "analysis.npz")

        def shot_conversion(a, shot=shot, n=n):
            return convert_files(data / "lenslet" / f"{shot}.png", data / "calib.xml",
                                 data / "camera.yaml", n, settings,
                                 setup_json=res / "views" / "convert_setup.json", analysis=a)

        layout = shot_conversion(analysis).layout
        depth = read_npy(res / "ground_truth" / "depth" / shot / f"{centre}.npy")
        true = oracle_patch(layout, depth, truth[f"{shot}/{centre}"], truth[f"{shot}/{right}"])
        patch = analysis.patch.patch.copy()
        est = patch[layout.lens_index].astype(float)
        ok = np.isfinite(true)
        errors.append(100.0 * float(np.median(np.abs(est[ok] / true[ok] - 1.0))))
        patch[layout.lens_index] = np.where(ok, true, est).astype(np.float32)
        oracle = dataclasses.replace(analysis,
                                     patch=dataclasses.replace(analysis.patch, patch=patch))
        conv = shot_conversion(oracle)
        for views in conv.view_groups(list(files), threads=2):
            times = {k: os.stat(files[k]) for k in views}
            write_images(((files[k], img) for k, img in views.items()), 2)
            for k, st in times.items():
                os.utime(files[k], ns=(st.st_atime_ns, st.st_mtime_ns))
    return errors


def figures(work: Path) -> dict:
    """The complete calibration's errors against the truth and the refinement's median."""
    res = work / "results" / DATASET
    g = read_json(res / "eval" / "gt_errors.json")["complete"]
    r = read_json(res / "calibration" / "refine.json")
    return {"focal": g["focal_err_signed_pct"], "centres": g["centre_rmse_mm"],
            "rotation": g["rotation_err_deg"]["max"],
            "median": r["observations"]["after"]["median_px"], "kept": not r["rejected"]}


def view_rules(src: Path, cfg: dict) -> list[str]:
    """The rules that read the replaced views, to run again (their mtimes are kept, so
    that the conversion's followers stay as they are): SIFT of every view (rules
    ``view_features_<k>``, the view matches and ``refine.tracks: views``), and with
    ``refine.tracks: both`` (the default) or ``central`` rule ``match_central`` (the
    central views' own SIFT) and rule ``refine`` (whose alignment reads every view).
    Without the last two a central-tracks capture's refinement is not run again, and every
    kind reads as the converted views."""
    sift_jobs = len(list((src / "results" / DATASET / "benchmarks" / "view_features").glob("*")))
    rules = [f"view_features_{k}" for k in range(sift_jobs)]
    if cfg["refine"]["tracks"] != "views":
        rules += ["match_central", "refine"]
    return rules


def run(capture: str, kind: str, softness: tuple[float, float]) -> tuple[dict, str]:
    """One capture with its views of ``kind``: the figures and a note."""
    src = OUT / capture
    work = WORK / f"{capture}-{kind}"
    shutil.rmtree(work, ignore_errors=True)
    work.parent.mkdir(parents=True, exist_ok=True)
    clone_capture(src, work)
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    valid = validate_config(cfg)  # the config with its defaults, validated once
    t0 = time.perf_counter()
    note = ""
    if kind == "oracle":
        true_depth_maps(work, cfg)
        err = rerender_with_oracle(work, valid)
        note = f"patch sizes {min(err):.2f}-{max(err):.2f} % off the truth (shot medians)"
    else:
        sigma = softness[0] if kind in ("blur", "noise") else 0.0
        noise = softness[1] if kind == "noise" else 0.0
        replace_by_renders(work, valid, sigma, noise)
        note = (f"sigma {sigma:.2f} px" if kind == "blur" else
                f"sigma {sigma:.2f} px, noise {noise:.2f}" if kind == "noise" else "")
    t1 = time.perf_counter()
    run_capture(work, cfg, view_rules(src, valid), 2,
                targets=("eval/gt_errors.json",))
    note += f"{'; ' if note else ''}views {t1 - t0:.0f} s, rerun {time.perf_counter() - t1:.0f} s"
    return figures(work), note


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("captures", nargs="+", help="kept captures of bench_accuracy.py")
    ap.add_argument("--kinds", nargs="+", choices=KINDS, default=list(KINDS))
    a = ap.parse_args()
    for capture in a.captures:  # all of them before the first one's long runs
        require_kept_capture(OUT / capture)
    out = Lines()
    out.head("capture", "views", "focal %", "centres mm", "rotation deg",
             "median px after", "note")
    for capture in a.captures:
        res = OUT / capture / "results" / DATASET
        key = held_central(res)
        ideal = WORK / f"{capture}-softness.png"  # the held central view's ideal render
        ideal.parent.mkdir(parents=True, exist_ok=True)
        data = OUT / capture / "data" / DATASET
        cfg = validate_config(yaml.safe_load((OUT / capture / "config.yaml").read_text()))
        render_views(data / "truth" / "scene.json", res / "ground_truth" / "cameras.json",
                     [key], int(cfg["datasets"][DATASET]["simulate"]["render"][
                         "ideal_supersample"]), [ideal], [ideal.with_suffix(".npy")],
                     log=lambda *x: None)
        softness = fitted_softness(_grey(view_files(res)[key]), _grey(ideal))
        ideal.with_suffix(".npy").unlink()
        f = figures(OUT / capture)
        rows = [("ours", f, f"fitted on {key}: sigma {softness[0]:.2f} px, "
                 f"noise {softness[1]:.2f} grey levels")]
        for kind in a.kinds:
            rows.append((kind, *run(capture, kind, softness)))
        for kind, f, note in rows:
            out.say(f"| {capture} | {kind} | {f['focal']:+.3f} | {f['centres']:.4f} | "
                    f"{f['rotation']:.4f} | {f['median']:.3f}"
                    f"{'' if f['kept'] else ' (not kept)'} | {note} |")


if __name__ == "__main__":
    main()
