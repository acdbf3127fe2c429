"""Rules synthesis_exp1..3: one view-synthesis experiment of Fig. 6 - read the inputs,
run plenocal.verify.synthesis.synthesis_job, write the result and its images; for a
split experiment (Exp. 3), rule synthesis_exp<k>_part runs one camera set
(synthesis_runs) and rule synthesis_exp<k> joins the parts (synthesis_result)."""

import os
from pathlib import Path

import cv2  # first: see DESIGN.md on cv2/pycolmap

from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.results import (
    read_synthesis_runs,
    write_synthesis,
    write_synthesis_runs,
)
from plenocal.artifacts.rig import read_rig
from plenocal.depth.inputs import rig_bounds
from plenocal.io.files import read_npy, to_uint8, write_image
from plenocal.names import file_key
from plenocal.rulelog import rule_logger
from plenocal.verify.experiments import layout_from_cams
from plenocal.verify.synthesis import synthesis_job, synthesis_result, synthesis_runs

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "synthesis")
cv2.setNumThreads(max(1, int(snakemake.threads)))  # the job's cores only (the DIBR's remaps)

cfg = dict(snakemake.params.verify)
cfg["depth"] = dict(snakemake.params.depth)
views_dir = Path(snakemake.params.views_dir)
near, far = rig_bounds(read_rig(snakemake.input.rig), float(cfg["depth"]["bounds_margin"]))


def load_depths(paths):
    """{"<cam>/<view>": z-depth} of results/.../<cam>/<view>.npy files."""
    return {file_key(p): read_npy(p) for p in paths}


depths = {"estimated": load_depths(snakemake.input.depth)}
if snakemake.input.get("true_depth"):
    depths["true"] = load_depths(snakemake.input.true_depth)
    # the targets' true depth (Exps. 1 and 2): their surface pixels
    depths["true"].update(load_depths(snakemake.input.get("true_depth_targets", [])))
# each camera set's runs with estimated depth on maps made with its own cameras: the
# ground-truth cameras' from rule depth_view_truth (plenocal.verify.synthesis)
own_depths = {}
if snakemake.input.get("truth_depth"):
    own_depths["ground_truth"] = load_depths(snakemake.input.truth_depth)
cameras = {"complete": read_cameras(snakemake.input.calibration)}
if snakemake.input.get("truth"):
    cameras["ground_truth"] = read_cameras(snakemake.input.truth)
experiment = int(snakemake.params.experiment)
layout = layout_from_cams(list(snakemake.params.array_cams), int(snakemake.params.n_views))


def image_path(cam: str, view: str) -> str:
    return str(views_dir / cam / f"{view}.png")


if snakemake.rule.endswith("_part"):
    part = snakemake.wildcards.cameras
    write_synthesis_runs(snakemake.output.runs, snakemake.output.kept, synthesis_runs(
        experiment, {part: cameras[part]}, depths, image_path, layout, near, far, cfg,
        int(snakemake.threads), own_depths))
else:
    synth_dir = Path(snakemake.output.synth)
    rel = Path(os.path.relpath(synth_dir, Path(snakemake.output.json).parent)).as_posix()
    if snakemake.input.get("runs"):
        parts = [read_synthesis_runs(j, k)
                 for j, k in zip(snakemake.input.runs, snakemake.input.kept, strict=True)]
        runs = parts[0]
        for p in parts[1:]:
            runs = runs.joined(p)
        result, files = synthesis_result(runs, depths, near, far, cfg, rel)
    else:
        result, files = synthesis_job(experiment, cameras, depths, image_path, layout, near,
                                      far, cfg, int(snakemake.threads), rel, own_depths)
    for name, img in files.items():
        write_image(synth_dir / name, to_uint8(img))
    synth_dir.mkdir(parents=True, exist_ok=True)
    write_synthesis(snakemake.output.json, result)
