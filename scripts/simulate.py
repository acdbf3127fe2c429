"""Rule simulate: trace the lenslet images of a dataset's shots, on the job's threads."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)
import numba

from plenocal.rulelog import rule_logger
from plenocal.simulate.dataset import render_shots

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "simulate")
numba.set_num_threads(max(1, min(int(snakemake.threads), numba.config.NUMBA_NUM_THREADS)))
data_dir = Path(snakemake.input.calib).parent
outputs = list(snakemake.output)
log.info("%d lenslet images on %d thread(s)", len(outputs), numba.get_num_threads())
render_shots(snakemake.params.sim, data_dir, [Path(p).stem for p in outputs], outputs,
             log=log.info)
