"""The dB lost to calibration with the true depth, taken apart (issue 32, item 4).

For a finished synthetic run (a Snakemake working folder whose Exp. 1 and Exp. 2 have run),
renders Exp. 1 and Exp. 2 with the true depth of the inputs, by our DIBR and, where an RVS
binary is given, by RVS, with

* the complete calibration, the ground-truth cameras, and the ground-truth cameras with
  each principal point moved by at most 1e-4 px (seeded per view): geometrically the same
  cameras, but no longer exactly aligned, which tells what the renderer makes of the
  exactness alone;
* the converted views as inputs and targets (what the workflow scores), and the ideal
  pinhole renders of the ground-truth cameras instead (no converter: the true depth and
  the true cameras are exact for them, so the true cameras must win);

and scores each target over the whole view (the workflow's PSNR: the run's
``verify.psnr_border_px``, the schema's 8 where its config leaves it out) and over its
surface pixels (:mod:`plenocal.verify.surface`, as the workflow's ``surface_psnr_db``).
Near occlusion edges every renderer decides per pixel which surface it shows, and with
cameras that differ by a fraction of a pixel that decision, not the calibration, moves a
target's PSNR by up to 1 dB; the surface PSNR is what the calibration alone changes.

Usage::

    python bench/bench_gt_synthesis.py WORKDIR [--rvs PATH_TO_RVS]
"""

from __future__ import annotations

import argparse
import zlib
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)
import numpy as np
import yaml
from bench_accuracy import require_kept_capture
from benchmd import binary_problem

from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.rig import read_rig
from plenocal.camera import PinholeCamera
from plenocal.depth.inputs import rig_bounds
from plenocal.io.files import read_image, read_npy, to_float
from plenocal.verify.experiments import experiment_plan, layout_from_cams
from plenocal.verify.surface import masked_error, psnr_of_error, surface_mask
from plenocal.verify.synthesis import SynthesisContext, synthesis_config

DATASET = "synthetic"


def jitter(cams: dict[str, PinholeCamera], eps: float) -> dict[str, PinholeCamera]:
    """The cameras with each principal point moved by up to ``eps`` px (seeded by name)."""
    out = {}
    for key, c in cams.items():
        rng = np.random.default_rng(zlib.crc32(key.encode()))
        K = c.K.copy()
        K[:2, 2] += eps * rng.uniform(-1.0, 1.0, 2)
        out[key] = PinholeCamera(K, c.cam_to_world, c.width, c.height)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("workdir", type=Path)
    ap.add_argument("--rvs", help="an RVS 4.0 binary: also render with RVS")
    args = ap.parse_args()
    if args.rvs:  # before the first DIBR pass, which the missing binary came after
        what = binary_problem(Path(args.rvs))
        if what:
            ap.error(f"--rvs {args.rvs}: {what}; build RVS 4.0 from its source (README, 'MPEG "
                     "exports and RVS'): python -m plenocal.verify.rvs <rvs-4.0-src.tar.gz> "
                     "prints the binary's path")
    require_kept_capture(args.workdir, ("eval/synthesis_exp1.json", "eval/synthesis_exp2.json"),
                         "bench/bench_accuracy.py runs Exp. 1 (without --no-exp1), not Exp. 2: "
                         f"run Snakemake on results/{DATASET}/eval/synthesis_exp2.json in it")
    res = args.workdir / "results" / DATASET
    cfg_doc = yaml.safe_load((args.workdir / "config.yaml").read_text()) or {}
    cfg = synthesis_config({**(cfg_doc.get("verify") or {}), "depth": cfg_doc.get("depth")})
    n = int(cfg_doc["datasets"][DATASET]["views"])
    border = int(cfg["psnr_border_px"])  # the run's, as its synthesis_exp<k>.json
    truth = read_cameras(res / "ground_truth" / "cameras.json")
    sets = {"complete": read_cameras(res / "calibration" / "cameras.json"),
            "ground_truth": truth, "gt+-1e-4px": jitter(truth, 1e-4)}
    layout = layout_from_cams(sorted({k.split("/")[0] for k in truth
                                      if k.startswith("x")}), n)
    near, far = rig_bounds(read_rig(res / "reg_b" / "rig.json"),
                           float(cfg["depth"]["bounds_margin"]))

    def depth(key: str) -> np.ndarray:
        cam, view = key.split("/")
        return read_npy(res / "ground_truth" / "depth" / cam / f"{view}.npy")

    folders = {"converted": res / "views", "ideal": res / "ground_truth" / "renders"}
    renderers = ["dibr"] + (["rvs"] if args.rvs else [])
    print("mean PSNR (dB) over the targets, true depth: whole view / surface pixels")
    for exp in (1, 2):
        (inputs, targets), = experiment_plan(layout, exp).values()
        masks = {t: surface_mask(t, inputs, truth, depth, border) for t in targets}
        for source, folder in folders.items():
            for renderer in renderers:
                row = []
                for name, cams in sets.items():
                    if renderer == "rvs" and name not in ("complete", "ground_truth"):
                        continue
                    ctx = SynthesisContext(
                        cams, lambda c, v, f=folder: str(f / c / f"{v}.png"), layout, near,
                        far, {**cfg, "renderer": renderer, "rvs_binary": args.rvs},
                        {k: depth(k) for k in inputs})
                    out = ctx.render(inputs, targets)
                    whole, surf = [], []
                    for t in targets:
                        img = to_float(read_image(folder / t.split("/")[0]
                                                  / f"{t.split('/')[1]}.png"))
                        d2 = ((out[t] - img) ** 2).mean(axis=2)
                        inner = d2[border:-border, border:-border] if border else d2
                        whole.append(-10 * np.log10(inner.mean()))
                        surf.append(psnr_of_error(*masked_error(out[t], img, masks[t])))
                    row.append(f"{name} {np.mean(whole):.2f} / {np.mean(surf):.2f}")
                print(f"Exp. {exp}, {source:9s} {renderer:4s}: " + ", ".join(row), flush=True)


if __name__ == "__main__":
    main()
