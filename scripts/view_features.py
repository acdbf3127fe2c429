"""Rule view_features: SIFT of the subaperture views of one shot, a part of the view
database (plenocal.calib.reg_a.viewdb); needs no calibration."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a import viewdb
from plenocal.io.files import make_temp_dir
from plenocal.names import file_key
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
views = {file_key(p): p for p in sm.input.views}
out_db = Path(sm.output[0])
out_db.parent.mkdir(parents=True, exist_ok=True)
# the database moves into place only once complete; a killed job's temporary folder is
# removed by the next run (make_temp_dir)
work = make_temp_dir(out_db.parent, f".{out_db.stem}.")
try:
    viewdb.extract_view_features(views, work / "features.db", work,
                                 max_num_features=cfg["max_num_features"], seed=cfg["seed"],
                                 extractor=cfg["sift"],
                                 num_threads=sm.threads)
    (work / "features.db").replace(out_db)
finally:
    shutil.rmtree(work, ignore_errors=True)
