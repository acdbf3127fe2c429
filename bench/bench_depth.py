"""Depth quality and speed: SGM and the plane sweep beside OpenCV's StereoSGBM, and the
view synthesis they give.

    python bench/bench_depth.py [--dataset synthetic] [--cam x03_y01] [--results DIR]

With a dataset whose ground truth exists (results/<d>/ground_truth/: cameras.json and
depth/<cam>/<view>.npy) the reference is the central view of ``cam`` with the
ground-truth cameras: plane sweep from the other views of its set (as registration B)
and from the central views of the neighbouring shots (as registration A), and SGBM
on the rectified pair (central view, next central view to the right). Without one,
a textured slanted plane rendered by synth.planes is used. Prints the
share of valid pixels, the share within 1 % of the true depth, and the throughput in
megapixels x depth labels per second.

With ``--results DIR`` (a folder whose rules depth_view and synthesis_exp<k> ran, e.g. a
worktree's ``results/<dataset>``) it also prints, per synthesis input view, the depth
quality of rule depth_view against the true depth, and per experiment the mean PSNR by
renderer, camera set and depth, with the dB lost to calibration (same depth) and to
depth."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # synth: test inputs

from benchmd import Lines, update_sections  # noqa: E402
from synth.planes import (  # noqa: E402
    camera_at,
    fronto_plane,
    photo_texture,
    render_plane,
)

from plenocal.artifacts.cameras import read_cameras  # noqa: E402
from plenocal.artifacts.results import (  # noqa: E402
    CAMERA_SETS,
    DEPTHS,
    PsnrStats,
    read_synthesis,
)
from plenocal.depth.inputs import nearest_sources  # noqa: E402
from plenocal.depth.planesweep import (  # noqa: E402
    PlaneSweepOptions,
    choose_num_depths,
    plane_sweep_depth,
)
from plenocal.depth.quality import depth_quality  # noqa: E402
from plenocal.depth.sgbm import sgbm_depth  # noqa: E402
from plenocal.depth.sgm import SgmOptions, sgm_depth  # noqa: E402
from plenocal.io.files import read_image, read_json, read_npy  # noqa: E402
from plenocal.names import file_key  # noqa: E402

#: the depth bounds (m) searched where there is no ground truth, about the slanted plane
#: (through 0.6 m, tilted by 30 deg): --near and --far are the ground truth's
PLANE_BOUNDS = (0.4, 0.9)


def run_sweep(out, label, ref, img, srcs, simgs, near, far, gt, opt):
    n = choose_num_depths(ref, srcs, near, far, opt)
    t = time.perf_counter()
    d = plane_sweep_depth(ref, img, srcs, simgs, near, far, opt)
    dt = time.perf_counter() - t
    q = depth_quality(d, gt, 0.01, border=8)
    passes = 2 if opt.lr_check else 1
    mpl = ref.width * ref.height / 1e6 * n * passes / dt
    out.say(f"{label:34s} valid {q['valid_share']:6.1%}  within 1% {q['within_share']:6.1%} "
          f"(of valid {q['within_of_valid']:6.1%})  median rel {q['median_rel_error']:.4f}  "
          f"{dt:6.2f} s  {n} labels x {len(srcs)} sources  {mpl:7.1f} MP*labels/s")


def run_sgm(out, label, ref, img, srcs, simgs, near, far, gt, opt):
    t = time.perf_counter()
    d = sgm_depth(ref, img, srcs, simgs, near, far, opt)
    dt = time.perf_counter() - t
    q = depth_quality(d, gt, 0.01, border=8)
    out.say(f"{label:34s} valid {q['valid_share']:6.1%}  within 1% {q['within_share']:6.1%} "
            f"(of valid {q['within_of_valid']:6.1%})  median rel {q['median_rel_error']:.4f}  "
            f"{dt:6.2f} s  {len(srcs)} sources (SGM, 8 directions, consistency check)")


def run_sgbm(out, label, c1, i1, c2, i2, near, far, gt):
    t = time.perf_counter()
    d, info = sgbm_depth(c1, i1, c2, i2, near, far)
    dt = time.perf_counter() - t
    q = depth_quality(d, gt, 0.01, border=8)
    mpl = c1.width * c1.height / 1e6 * info["num_disparities"] / dt
    out.say(f"{label:34s} valid {q['valid_share']:6.1%}  within 1% {q['within_share']:6.1%} "
          f"(of valid {q['within_of_valid']:6.1%})  median rel {q['median_rel_error']:.4f}  "
          f"{dt:6.2f} s  {info['num_disparities']} disparities      {mpl:7.1f} MP*labels/s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=None, help="also write the figures into this BENCHMARKS.md")
    ap.add_argument("--dataset", default="synthetic",
                    help="the dataset whose ground truth (results/<dataset>/ground_truth, "
                         "under the current folder) is the reference; without it the "
                         "slanted plane is, and --cam, --near and --far do not apply")
    ap.add_argument("--cam", default=None,
                    help="with the ground truth: the reference shot (default: the middle one)")
    ap.add_argument("--near", type=float, default=0.47 * 0.85,
                    help="with the ground truth: the nearest depth searched (m)")
    ap.add_argument("--far", type=float, default=0.74 * 1.15,
                    help="with the ground truth: the farthest depth searched (m)")
    ap.add_argument("--results", default=None,
                    help="results/<dataset> folder with depth_view and synthesis outputs")
    a = ap.parse_args()
    if a.results and not Path(a.results).is_dir():
        ap.error(f"--results {a.results}: no such folder (give a run's results/<dataset>)")
    sections = {}
    if not a.results:  # with --results only the figures of that run
        out = Lines()
        measure(a, out)
        sections["Plane sweep against StereoSGBM (quality and throughput)"] = [
            "`python bench/bench_depth.py` (one process, the same views):", "", "```", *out,
            "```"]
    else:
        syn = Lines()
        synthesis_figures(Path(a.results), syn)
        if not syn:  # an empty section must not pass for a measured one
            sys.exit(f"--results {a.results}: no depth map of rule depth_view with its true "
                     "depth (depth/views/, ground_truth/depth/) and no "
                     "eval/synthesis_exp<k>.json: give a run's results/<dataset> whose "
                     "rules depth_view and synthesis_exp<k> ran")
        sections["Depth for view synthesis and RVS"] = [
            f"`python bench/bench_depth.py --results {a.results}` (rules depth_view and "
            "synthesis_exp<k> of a default run; PSNR in dB, mean over the targets):", "",
            "```", *syn, "```", "",
            "Depth: rule depth_view (SGM) with the complete calibration against the true "
            "depth. Each experiment renders the same depth maps with the complete and the "
            "ground-truth cameras (the dB lost to calibration) and again with the true "
            "depth; `rvs` is RVS 4.0 (`verify.renderer: rvs`), `dibr` the project's "
            "renderer on the same inputs."]
    if a.out:
        update_sections(a.out, sections)


def synthesis_figures(root: Path, out: Lines) -> None:
    """Depth quality of rule depth_view and the synthesis PSNR of every experiment."""
    for p in sorted((root / "depth" / "views").glob("*/*.npy")):
        key = file_key(p)
        gt = root / "ground_truth" / "depth" / p.parent.name / p.name
        if not gt.is_file():
            continue
        q = depth_quality(read_npy(p), read_npy(gt), 0.01, border=8)
        info = read_json(p.with_suffix(".json"))
        out.say(f"depth {key:14s} {info['method']:10s} valid {q['valid_share']:6.1%}  "
                f"within 1% {q['within_share']:6.1%}  median rel {q['median_rel_error']:.4f}")
    for k in (1, 2, 3):
        path = root / "eval" / f"synthesis_exp{k}.json"
        if not path.is_file():
            continue
        res = read_synthesis(path)
        for name in res.renderers:
            for depth in DEPTHS:
                for cams in CAMERA_SETS:
                    stats = res.psnr_stats(name, depth, cams)
                    if stats:
                        out.say(f"Exp. {k} {name:5s} {depth:9s} depth, {cams:12s} cameras: "
                                + _psnr_text(stats))
            est, true = ("estimated", "complete"), ("true", "complete")
            out.say(f"Exp. {k} {name:5s} dB lost to calibration (same depth): "
                    f"{_db(res.mean_db_lost(name, est, ('estimated', 'ground_truth')))}; with the "
                    f"true depth: {_db(res.mean_db_lost(name, true, ('true', 'ground_truth')))}; "
                    f"to depth: {_db(res.mean_db_lost(name, est, true))}")


def _db(lost: dict[str, float]) -> str:
    """The dB lost per part of the experiment ("" for the whole of Exps. 1-2)."""
    if not lost:
        return "-"
    if set(lost) == {""}:
        return f"{lost['']:.2f}"
    return ", ".join(f"{part} {v:.2f}" for part, v in lost.items())


def _psnr_text(stats: dict[str, PsnrStats]) -> str:
    if set(stats) == {""}:
        s = stats[""]
        return f"{s.mean_db:.2f} (min {s.min_db:.2f}, {s.count} views)"
    return "; ".join(f"{part} {s.mean_db:.2f}" for part, s in stats.items())


def measure(a, out: Lines) -> None:
    opt = PlaneSweepOptions()
    gt_dir = Path("results") / a.dataset / "ground_truth"
    if (gt_dir / "cameras.json").is_file():
        cams = read_cameras(gt_dir / "cameras.json")
        shots = sorted({k.split("/")[0] for k in cams if k.startswith("x")})
        views = sorted({k.split("/")[1] for k in cams})
        n = int(round(len(views) ** 0.5))
        cv = f"{(n - 1) // 2}_{(n - 1) // 2}"
        cam = a.cam or shots[len(shots) // 2]
        ref_key = f"{cam}/{cv}"
        img = read_image(Path("results") / a.dataset / "views" / cam / f"{cv}.png")
        gt = read_npy(gt_dir / "depth" / cam / f"{cv}.npy")

        def load(k):
            c, v = k.split("/")
            return read_image(Path("results") / a.dataset / "views" / c / f"{v}.png")

        own = [f"{cam}/{v}" for v in views if f"{cam}/{v}" in cams]
        src_b = nearest_sources(ref_key, cams, 8, own)
        src_a = nearest_sources(ref_key, cams, 6, [f"{s}/{cv}" for s in shots])
        out.say(f"reference {ref_key} ({cams[ref_key].width}x{cams[ref_key].height}), "
              f"ground-truth cameras, bounds [{a.near:.3f}, {a.far:.3f}] m")
        for label, src in (("plane sweep, own set (B)", src_b),
                           ("plane sweep, neighbour shots (A)", src_a)):
            run_sweep(out, label, cams[ref_key], img, [cams[k] for k in src],
                      [load(k) for k in src], a.near, a.far, gt, opt)
        # the synthesis depth's sources: 4 nearest shots' same view + 4 own-set views
        src_s = nearest_sources(ref_key, cams, 4, [f"{s}/{cv}" for s in shots])
        src_s += nearest_sources(ref_key, cams, 4, own)
        for label, fn, o in (("plane sweep, synthesis sources", run_sweep, opt),
                             ("SGM, synthesis sources", run_sgm, SgmOptions())):
            fn(out, label, cams[ref_key], img, [cams[k] for k in src_s],
               [load(k) for k in src_s], a.near, a.far, gt, o)
        def offset(k):  # source centre in the reference camera frame
            return (cams[ref_key].world_to_cam @ cams[k].cam_to_world)[:3, 3]

        horiz = [k for k in src_a if abs(offset(k)[0]) > 2 * abs(offset(k)[1])]
        right = min(horiz, key=lambda k: float(np.linalg.norm(offset(k))))
        run_sweep(out, "plane sweep, same pair as SGBM", cams[ref_key], img, [cams[right]],
                  [load(right)], a.near, a.far, gt,
                  PlaneSweepOptions(lr_check=False, best_fraction=1.0))
        run_sgbm(out, f"StereoSGBM {ref_key} + {right}", cams[ref_key], img, cams[right],
                 load(right), a.near, a.far, gt)
        return
    near, far = PLANE_BOUNDS
    out.say(f"no ground truth under results/{a.dataset}/: textured slanted plane, 320x240, "
            f"2 cm baseline, bounds [{near:.3f}, {far:.3f}] m (--cam, --near and --far apply "
            "to the ground truth only)")
    tex = photo_texture(512)
    plane = fronto_plane(0.6, 0.8, tex, 30.0)
    ref = camera_at([0, 0, 0], 500.0, 320, 240)
    srcs = [camera_at([dx * 0.02, dy * 0.02, 0], 500.0, 320, 240)
            for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    img, gt = render_plane(ref, plane)
    simgs = [render_plane(s, plane)[0] for s in srcs]
    run_sweep(out, "plane sweep, 8 sources", ref, img, srcs, simgs, near, far, gt, opt)
    run_sgm(out, "SGM, 8 sources", ref, img, srcs, simgs, near, far, gt, SgmOptions())
    right = srcs[6]  # (+1, 0)
    run_sweep(out, "plane sweep, same pair as SGBM", ref, img, [right], [simgs[6]], near, far,
              gt, PlaneSweepOptions(lr_check=False, best_fraction=1.0))
    run_sgbm(out, "StereoSGBM", ref, img, right, simgs[6], near, far, gt)


if __name__ == "__main__":
    main()
