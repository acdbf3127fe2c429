"""Rules ground_truth_render (one view) and ground_truth_render_set (the other views of
the full-set shot, in one job): ideal pinhole renders and z-depth maps."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.rulelog import rule_logger
from plenocal.simulate.groundtruth import render_views

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "ground_truth_render")


def paths(x) -> list[str]:
    """A named output as a list: one path (ground_truth_render) or several (_set)."""
    return [x] if isinstance(x, str) else list(x)


images = paths(snakemake.output.image)
render_views([p for p in snakemake.input if p.endswith("scene.json")][0], snakemake.input.cams,
             snakemake.wildcards.cam, [Path(p).stem for p in images],
             int(snakemake.params.supersample), images, paths(snakemake.output.depth),
             log=log.info)
