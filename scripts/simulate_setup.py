"""Rule simulate_setup: scene, shots, optics, calib.xml and camera.yaml of a synthetic dataset."""

import logging
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.simulate.dataset import setup_dataset

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
out_dir = Path(snakemake.output.calib).parent
setup_dataset(snakemake.params.sim, out_dir)
logging.info("wrote the synthetic dataset description into %s", out_dir)
