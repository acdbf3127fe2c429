"""Rule ground_truth_cam: traced pinhole cameras of every view of one shot."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.convert.setup import read_setup
from plenocal.rulelog import rule_logger
from plenocal.simulate.groundtruth import ground_truth_shot

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "ground_truth_cam")
conv = snakemake.params.convert
ground_truth_shot(Path(snakemake.input.calib).parent, snakemake.wildcards.cam,
                  int(snakemake.params.views), read_setup(snakemake.input.setup).tile,
                  conv["view_spacing_px"], snakemake.output[0],
                  log=log.info, even=bool(conv["even_size"]))
