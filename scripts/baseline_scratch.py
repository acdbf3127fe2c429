"""Rule baseline_scratch: plain SfM of all views from scratch (Table I's remark that
it fails or registers only part of the views)."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.io.files import make_temp_dir, write_json
from plenocal.rulelog import log_to_file
from plenocal.verify.sfm_baselines import scratch_sfm

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
# COLMAP's working files beside the output, not in $TMPDIR (see baseline_sfm.py)
work = make_temp_dir(Path(sm.output[0]).parent, ".baseline_scratch.")
try:
    result = scratch_sfm(sm.input.database, seed=sm.params.sfm["seed"], num_threads=sm.threads,
                         work_dir=work)
finally:
    shutil.rmtree(work, ignore_errors=True)
write_json(sm.output[0], result)
