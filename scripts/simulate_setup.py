"""Rule simulate_setup: scene, shots, optics, calib.xml and camera.yaml of a synthetic dataset."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.rulelog import rule_logger
from plenocal.simulate.dataset import setup_dataset

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "simulate_setup")
out_dir = Path(snakemake.output.calib).parent
setup_dataset(snakemake.params.sim, out_dir)
log.info("wrote the synthetic dataset description into %s", out_dir)
