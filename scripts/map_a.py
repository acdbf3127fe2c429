"""Rule map_a: incremental (or global) mapping of registration A; writes the COLMAP
model and reg_a.json."""
import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.artifacts.reg_a import write_reg_a
from plenocal.calib.reg_a.colmap import check_database
from plenocal.calib.reg_a.sfm import map_a
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
check_database(sm.input.db, "delete it and run again: rule match_a makes it anew")
reg = map_a(sm.input.db, sm.input.images, sm.output.model, mapper=cfg["mapper"],
            seed=cfg["seed"], num_threads=sm.threads)
write_reg_a(sm.output.reg_a, reg)
