"""The noise floor of the dB lost to calibration with estimated depth (issue 32, item 4).

With ``verify.ground_truth_own_depth`` each camera set renders Exp. 1 on depth maps made
with its own cameras (rules ``depth_view`` and ``depth_view_truth``), and the difference
of the two is the dB lost to calibration with estimated depth. Semi-global matching
answers a change of the cameras far below any calibration error with other maps: where
it places an occlusion edge, which disparity wins on a weak texture. This script measures
how far that alone moves the figure.

For each finished synthetic run given (a Snakemake working folder of
``bench/bench_accuracy.py``, ``bench/out/accuracy/<capture>``, whose Exp. 1 ran with
``verify.ground_truth_own_depth: true``), every ground-truth camera is moved by a
negligible amount (its centre by ``--move-um`` micrometres and its axes by
``--turn-deg`` degrees, each in a random direction, seeded per draw; 1 um and 1e-4 deg are
7-45x below the calibrations' own centre and rotation errors on the four captures
measured), the inputs' depth
maps are estimated again with the moved cameras as rule ``depth_view_truth`` makes them,
and Exp. 1 is rendered with the unmoved true cameras on them, by the project's DIBR,
scored over the whole views (border ``verify.psnr_border_px``) and over their surface
pixels (:mod:`plenocal.verify.surface`), as ``eval/synthesis_exp1.json``. The draws'
spread is the floor below which a dB lost with estimated depth says nothing about the
calibration; the run's own figures (complete and ground-truth cameras on their own maps,
and both on the true depth) are read from its ``synthesis_exp1.json``.

Usage::

    python bench/bench_depth_noise.py CAPTURE_DIR [CAPTURE_DIR ...] [--draws 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

import cv2  # (first: see DESIGN.md on cv2/pycolmap)
import numpy as np
import yaml
from bench_accuracy import require_kept_capture
from benchmd import positive_int

from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.results import PsnrTable, read_synthesis
from plenocal.artifacts.rig import read_rig
from plenocal.camera import PinholeCamera
from plenocal.config import with_defaults
from plenocal.depth.inputs import rig_bounds
from plenocal.depth.views import estimate_view_depth
from plenocal.io.files import read_image, read_npy
from plenocal.names import is_array_shot, split_key
from plenocal.verify.experiments import experiment_plan, layout_from_cams
from plenocal.verify.synthesis import (
    psnr_tables,
    run_experiment,
    surface_masks,
    synthesis_config,
)

DATASET = "synthetic"


def moved(cams: dict[str, PinholeCamera], seed: int, move_m: float, turn_deg: float
          ) -> dict[str, PinholeCamera]:
    """Every camera's centre moved by ``move_m`` and its axes turned by ``turn_deg``, each
    in a random direction (one generator per draw, cameras in name order)."""
    rng = np.random.default_rng(seed)
    out = {}
    for key in sorted(cams):
        c = cams[key]
        axis = rng.normal(size=3)
        turn, _ = cv2.Rodrigues(axis / np.linalg.norm(axis) * np.deg2rad(turn_deg))
        shift = rng.normal(size=3)
        pose = c.cam_to_world.copy()
        pose[:3, :3] = turn @ pose[:3, :3]
        pose[:3, 3] += shift / np.linalg.norm(shift) * move_m
        out[key] = dataclasses.replace(c, cam_to_world=pose)
    return out


def table_means(table: PsnrTable) -> tuple[float, float]:
    """(whole-view, surface) PSNR of a table, each averaged over its targets."""
    return table.mean_db, float(np.mean(list(table.surface_psnr_db.values())))


def run_figures(path: Path) -> dict[tuple[str, str], tuple[float, float]]:
    """(cameras, depth) -> (whole, surface) mean PSNR of the run's own DIBR tables."""
    out = {}
    for t in read_synthesis(path).tables:
        if t.renderer == "dibr" and (t.cameras, t.depth) not in out:
            out[t.cameras, t.depth] = table_means(t)
    return out


def capture_noise(work: Path, draws: int, move_m: float, turn_deg: float, threads: int
                  ) -> dict:
    res = work / "results" / DATASET
    cfg = yaml.safe_load((work / "config.yaml").read_text())
    depth_cfg = with_defaults("depth", cfg.get("depth"))
    verify = synthesis_config(cfg.get("verify", {}))
    verify["depth"] = depth_cfg
    figures = run_figures(res / "eval" / "synthesis_exp1.json")
    if ("ground_truth", "estimated") not in figures:
        raise SystemExit(f"{work}: Exp. 1 ran without verify.ground_truth_own_depth (run "
                         "bench_accuracy.py on it first)")
    n = int(cfg["datasets"][DATASET]["views"])
    truth = read_cameras(res / "ground_truth" / "cameras.json")
    near, far = rig_bounds(read_rig(res / "reg_b" / "rig.json"),
                           float(depth_cfg["bounds_margin"]))
    layout = layout_from_cams(sorted({split_key(k)[0] for k in truth
                                      if is_array_shot(split_key(k)[0])}), n)
    inputs, targets = experiment_plan(layout, 1)["exp1"]

    def image_path(cam: str, view: str) -> str:
        return str(res / "views" / cam / f"{view}.png")

    true_depth = {k: read_npy(res / "ground_truth" / "depth" / f"{k}.npy")
                  for k in inputs + targets}
    masks = surface_masks(1, layout, truth, true_depth, verify)
    images: dict[str, np.ndarray] = {}
    captured: dict[str, np.ndarray] = {}

    def image(key: str) -> np.ndarray:
        if key not in captured:
            captured[key] = read_image(image_path(*split_key(key)))
        return captured[key]

    border = int(verify["psnr_border_px"])
    rows = []
    for seed in range(1, draws + 1):
        t0 = time.perf_counter()
        cams = moved(truth, seed, move_m, turn_deg)
        maps = {k: estimate_view_depth(k, cams, image, near, far, n, depth_cfg,
                                       int(verify["depth_sources_shots"]),
                                       int(verify["depth_sources_set"]))[0] for k in inputs}
        result, _ = run_experiment(1, truth, image_path, layout, near, far,
                                   {**verify, "renderer": "dibr", "threads": threads}, maps,
                                   images, masks)
        table, = psnr_tables(1, {("dibr", "estimated", "ground_truth"): result}, ["dibr"],
                             border)
        rows.append(table_means(table))
        print(f"  {work.name}: draw {seed}: {rows[-1][0]:.3f} / {rows[-1][1]:.3f} dB "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    own = figures[("ground_truth", "estimated")]
    draw_whole = [r[0] for r in rows] + [own[0]]
    draw_surf = [r[1] for r in rows] + [own[1]]
    return {"figures": figures, "whole": draw_whole, "surface": draw_surf}


def spread(values: list[float]) -> str:
    return (f"{statistics.mean(values):.2f} (sd {statistics.stdev(values):.2f}, "
            f"{min(values):.2f}-{max(values):.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("captures", nargs="+", type=Path)
    ap.add_argument("--draws", type=positive_int, default=3)
    ap.add_argument("--move-um", type=float, default=1.0)
    ap.add_argument("--turn-deg", type=float, default=1e-4)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    for work in args.captures:
        require_kept_capture(work, ("eval/synthesis_exp1.json",))
    cv2.setNumThreads(args.threads)
    print(f"Exp. 1 with estimated depth, DIBR, mean PSNR of the targets (dB), whole views / "
          f"surfaces. The true cameras moved by {args.move_um:g} um and {args.turn_deg:g} "
          f"deg, {args.draws} draws, each on its own SGM maps, with the unmoved ones' own "
          "maps as one more: mean (sd, range). 'lost' is the ground-truth cameras' figure "
          "less the calibration's, each on its own maps; with the true depth both share "
          "the maps.\n")
    print("| capture | complete, own maps | true cameras, own maps | true cameras moved, "
          "own maps (whole) | (surfaces) | lost, whole / surfaces | lost with the true "
          "depth, whole / surfaces |")
    print("|---|---|---|---|---|---|---|")
    for work in args.captures:
        r = capture_noise(work, args.draws, args.move_um * 1e-6, args.turn_deg, args.threads)
        f = r["figures"]
        comp, gt = f[("complete", "estimated")], f[("ground_truth", "estimated")]
        ct, gtt = f[("complete", "true")], f[("ground_truth", "true")]
        print(f"| {work.name} | {comp[0]:.2f} / {comp[1]:.2f} | {gt[0]:.2f} / {gt[1]:.2f} | "
              f"{spread(r['whole'])} | {spread(r['surface'])} | "
              f"{gt[0] - comp[0]:+.2f} / {gt[1] - comp[1]:+.2f} | "
              f"{gtt[0] - ct[0]:+.2f} / {gtt[1] - ct[1]:+.2f} |", flush=True)


if __name__ == "__main__":
    main()
