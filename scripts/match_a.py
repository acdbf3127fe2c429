"""Rule match_a: exhaustive matching and geometric verification of registration A."""
import shutil

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a.colmap import resolve_sfm_device
from plenocal.calib.reg_a.sfm import match_a
from plenocal.io.files import write_json
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
use_gpu, _ = resolve_sfm_device(cfg)  # sfm.device
# matches go into a copy: the features database stays the input it was
tmp = sm.output.db + ".part"
shutil.copyfile(sm.input.db, tmp)
info = match_a(tmp, seed=cfg["seed"], num_threads=sm.threads, use_gpu=use_gpu)
shutil.move(tmp, sm.output.db)
write_json(sm.output.info, info)
