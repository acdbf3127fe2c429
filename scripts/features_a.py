"""Rule features_a: SIFT of the central views into the registration-A database."""
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a.sfm import features_a
from plenocal.io.files import write_json
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
views = {Path(p).parent.name: p for p in sm.input.views}
info = features_a(views, sm.output.images, sm.output.db,
                  max_num_features=cfg["max_num_features"], seed=cfg["seed"],
                  extractor=cfg["sift"],
                  num_threads=sm.threads)
write_json(sm.output.info, info)
