"""Rules ground_truth_render (one view), ground_truth_render_set (the other views of the
full-set shot) and ground_truth_render_central (the central view of every shot): ideal
pinhole renders and z-depth maps, the views named by the image paths
(``.../renders/<cam>/<view>.png``)."""


import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.names import file_key
from plenocal.rulelog import rule_logger
from plenocal.simulate.groundtruth import render_views

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "ground_truth_render")


def paths(x) -> list[str]:
    """A named output as a list: one path (ground_truth_render) or several (_set, _central)."""
    return [x] if isinstance(x, str) else list(x)


images = paths(snakemake.output.image)
render_views([p for p in snakemake.input if p.endswith("scene.json")][0], snakemake.input.cams,
             [file_key(p) for p in images],
             int(snakemake.params.supersample), images, paths(snakemake.output.depth),
             log=log.info)
