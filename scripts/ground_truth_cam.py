"""Rule ground_truth_cam: traced pinhole cameras of every view of one shot."""

import logging
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.convert.setup import read_setup
from plenocal.groundtruth import ground_truth_shot

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
conv = snakemake.params.convert
ground_truth_shot(Path(snakemake.input.calib).parent, snakemake.wildcards.cam,
                  int(snakemake.params.views), read_setup(snakemake.input.setup).tile,
                  conv["view_spacing_px"], snakemake.output[0],
                  log=logging.info, even=bool(conv["even_size"]))
