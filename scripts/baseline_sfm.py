"""Rule baseline_sfm: the naive "A+SfM" calibration of Table I."""

import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.artifacts.cameras import write_cameras
from plenocal.artifacts.reg_a import read_reg_a
from plenocal.io.files import make_temp_dir, write_json
from plenocal.rulelog import log_to_file
from plenocal.verify.sfm_baselines import baseline_sfm

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
# COLMAP's working files beside the outputs, not in $TMPDIR: removed at the end, and a
# killed job's by the next run of this rule (make_temp_dir)
work = make_temp_dir(Path(sm.output.info).parent, ".baseline_sfm.")
try:
    cameras, info = baseline_sfm(read_reg_a(sm.input.reg_a), sm.input.database,
                                 sm.params.central, seed=cfg["seed"], num_threads=sm.threads,
                                 work_dir=work)
finally:
    shutil.rmtree(work, ignore_errors=True)
write_cameras(sm.output.cameras, cameras, units="sfm")
write_json(sm.output.info, info)
