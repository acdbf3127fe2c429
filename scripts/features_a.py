"""Rule features_a: SIFT of the central views into the registration-A database."""
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a.colmap import resolve_sfm_device
from plenocal.calib.reg_a.sfm import features_a
from plenocal.io.files import write_json
from plenocal.malloc import keep_freed_memory
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
# SIFT's scale space per view, freed and allocated again: keep the heap (plenocal.malloc)
keep_freed_memory()
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
use_gpu, extractor = resolve_sfm_device(cfg)  # sfm.device and sfm.sift
views = {Path(p).parent.name: p for p in sm.input.views}
info = features_a(views, sm.output.images, sm.output.db,
                  max_num_features=cfg["max_num_features"], seed=cfg["seed"],
                  extractor=extractor,
                  num_threads=sm.threads, use_gpu=use_gpu)
write_json(sm.output.info, info)
