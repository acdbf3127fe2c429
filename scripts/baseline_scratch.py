"""Rule baseline_scratch: plain SfM of all views from scratch (Table I's remark that
it fails or registers only part of the views)."""
import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.io.files import write_json
from plenocal.rulelog import log_to_file
from plenocal.verify.sfm_baselines import scratch_sfm

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
write_json(sm.output[0], scratch_sfm(sm.input.database, seed=sm.params.sfm["seed"],
                                     num_threads=sm.threads))
