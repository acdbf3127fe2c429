"""Rule simulate: trace the lenslet image of one shot."""

import logging
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.simulate.dataset import render_shot

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
data_dir = Path(snakemake.input.calib).parent
render_shot(snakemake.params.sim, data_dir, snakemake.wildcards.cam, snakemake.output[0],
            log=logging.info)
