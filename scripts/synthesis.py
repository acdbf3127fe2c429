"""Rules synthesis_exp1..3: one view-synthesis experiment of Fig. 6. The inputs' depth
maps (rule depth_view, computed once with the complete calibration) are rendered with
the complete calibration and, on synthetic data, with the ground-truth cameras - the
same depth for both, so their difference is the dB lost to calibration - and again
with the true depth (the dB lost to depth). Renderer: verify.renderer (the project's
DIBR, or RVS with the DIBR beside it). See plenocal.verify.synthesis."""

import os
import time
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)
import numpy as np

from plenocal.artifacts.results import (
    DepthQuality,
    SynthesisResult,
    SynthesisSetup,
    SynthImage,
    write_synthesis,
)
from plenocal.artifacts.rig import read_rig
from plenocal.camera import read_cameras
from plenocal.depth.inputs import rig_bounds
from plenocal.depth.quality import depth_quality
from plenocal.io.files import to_uint8, write_image
from plenocal.names import key_shot
from plenocal.rulelog import rule_logger
from plenocal.verify.synthesis import (
    layout_from_cams,
    psnr_tables,
    run_experiment,
)

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "synthesis")

exp = int(snakemake.params.experiment)
cfg = dict(snakemake.params.verify)
cfg["depth"] = dict(snakemake.params.depth)
views_dir = Path(snakemake.params.views_dir)
layout = layout_from_cams(list(snakemake.params.array_cams), int(snakemake.params.n_views))
near, far = rig_bounds(read_rig(snakemake.input.rig), float(cfg["depth"]["bounds_margin"]))


def load_depths(paths):
    """{"<cam>/<view>": z-depth} of results/.../<cam>/<view>.npy files."""
    return {f"{Path(p).parent.name}/{Path(p).stem}": np.load(p) for p in paths}


depths = {"estimated": load_depths(snakemake.input.depth)}
if snakemake.input.get("true_depth"):
    depths["true"] = load_depths(snakemake.input.true_depth)
cameras = {"complete": read_cameras(snakemake.input.calibration)}
if snakemake.input.get("truth"):
    cameras["ground_truth"] = read_cameras(snakemake.input.truth)
renderers = [cfg.get("renderer", "dibr")]
if renderers[0] == "rvs" and cfg.get("rvs_compare_dibr", True):
    renderers.append("dibr")

runs, kept_all, images = {}, {}, {}
for renderer in renderers:
    for dname, dmaps in depths.items():
        for cname, cams in cameras.items():
            t0 = time.perf_counter()
            res, kept = run_experiment(exp, cams, lambda c, v: str(views_dir / c / f"{v}.png"),
                                       layout, near, far,
                                       {**cfg, "renderer": renderer,
                                        "threads": int(snakemake.threads)},
                                       dict(dmaps), images)
            seconds = time.perf_counter() - t0  # logged only: the file stays the same bits
            runs[(renderer, dname, cname)] = res
            log.info("%s, %s depth, %s cameras: experiment %d, %.1f s", renderer, dname, cname,
                     exp, seconds)
            if dname == "estimated" and renderer == renderers[0]:
                kept_all.update({(cname, k): img for k, img in kept.items()})

border = int(cfg.get("psnr_border_px", 8))
quality = {}
if "true" in depths:
    quality = {k: DepthQuality.from_dict(depth_quality(z, depths["true"][k], 0.01, border))
               for k, z in depths["estimated"].items() if k in depths["true"]}
setup = SynthesisSetup(near_m=near, far_m=far, psnr_border_px=border,
                       depth_method=cfg["depth"].get("synthesis_method", "sgm"),
                       depth_quality=quality,
                       # as experiment3 ran it (every run of Exp. 3 has the same)
                       view_stride=next(iter(runs.values()))["view_stride"] if exp == 3
                       else None)
synth_dir = Path(snakemake.output.synth)
kept_images = []
for (cname, k), img in sorted(kept_all.items()):
    # Exp. 3 keeps "<central|lateral>:<shot>/<view>", Exp. 2 the views of a set
    variant, _, view = k.rpartition(":")
    path = synth_dir / f"{cname}_{k.replace('/', '_').replace(':', '_')}.png"
    write_image(path, to_uint8(img))
    kept_images.append(SynthImage(
        Path(os.path.relpath(path, Path(snakemake.output.json).parent)).as_posix(), view, cname,
        variant or (key_shot(view) if exp == 2 else "")))
synth_dir.mkdir(parents=True, exist_ok=True)
write_synthesis(snakemake.output.json, SynthesisResult(
    experiment=exp, renderer=renderers[0], tables=tuple(psnr_tables(exp, runs, renderers)),
    setup=setup, images=tuple(kept_images)))
