"""Rule ground_truth: traced pinhole cameras of every view of every shot."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.convert.setup import read_setup
from plenocal.rulelog import rule_logger
from plenocal.simulate.groundtruth import ground_truth_cameras

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "ground_truth")
conv = snakemake.params.convert
setup = read_setup(snakemake.input.setup)  # the grid, tile and q every shot is cut with
ground_truth_cameras(Path(snakemake.input.calib).parent, list(snakemake.params.cams),
                     int(snakemake.params.views), setup.tile, setup.q_px, snakemake.output[0],
                     log=log.info, even=bool(conv["even_size"]),
                     insets_px=setup.border_cut.insets_px, grid_of=setup.grid)
