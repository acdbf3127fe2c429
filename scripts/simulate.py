"""Rule simulate: trace the lenslet image of one shot."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.rulelog import rule_logger
from plenocal.simulate.dataset import render_shot

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "simulate")
data_dir = Path(snakemake.input.calib).parent
render_shot(snakemake.params.sim, data_dir, snakemake.wildcards.cam, snakemake.output[0],
            log=log.info)
