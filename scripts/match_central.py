"""Rule match_central: the central views' SIFT at refine.central_contrast and their
exhaustive matching, as rules features_a and match_a make registration A's: the points of
refine.tracks: central (plenocal.calib.central_tracks)."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a.colmap import resolve_sfm_device
from plenocal.calib.reg_a.sfm import features_a, match_a
from plenocal.io.files import make_temp_dir, write_json
from plenocal.malloc import keep_freed_memory
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
keep_freed_memory()
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
use_gpu, extractor = resolve_sfm_device(cfg)  # sfm.device and sfm.sift
views = {Path(p).parent.name: p for p in sm.input.views}
out_db = Path(sm.output.db)
out_db.parent.mkdir(parents=True, exist_ok=True)
# the database moves into place only once complete; a killed job's temporary folder is
# removed by the next run (make_temp_dir)
work = make_temp_dir(out_db.parent, ".match_central.")
try:
    info = features_a(views, work / "images", work / "database.db",
                      max_num_features=cfg["max_num_features"], seed=cfg["seed"],
                      extractor=extractor, num_threads=sm.threads, use_gpu=use_gpu,
                      contrast=float(sm.params.contrast))
    info.update(match_a(work / "database.db", seed=cfg["seed"], num_threads=sm.threads,
                        use_gpu=use_gpu))
    (work / "database.db").replace(out_db)
finally:
    shutil.rmtree(work, ignore_errors=True)
write_json(sm.output.info, {"contrast": float(sm.params.contrast), **info})
