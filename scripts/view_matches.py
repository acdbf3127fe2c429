"""Rule view_matches: the shots' SIFT features merged into one database and the
matching of the pairs that Table I and the baseline share (plenocal.calib.reg_a.viewdb)."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.calib.reg_a import viewdb
from plenocal.calib.reg_a.colmap import resolve_sfm_device
from plenocal.io.files import make_temp_dir, write_json
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
use_gpu, _ = resolve_sfm_device(cfg)  # sfm.device
centres = {cam: c.centre for cam, c in read_reg_a(sm.input.reg_a).cameras.items()}
out_db = Path(sm.output.database)
out_db.parent.mkdir(parents=True, exist_ok=True)
# the database moves into place only once complete; a killed job's temporary folder is
# removed by the next run (make_temp_dir)
work = make_temp_dir(out_db.parent, ".view_matches.")
try:
    info = viewdb.merge_view_features(sm.input.features, work / "database.db")
    info.update(viewdb.match_views(work / "database.db", shot_centres=centres,
                                   shot_neighbours=cfg["view_matching"]["shot_neighbours"],
                                   view_radius=cfg["view_matching"]["view_radius"],
                                   within_shot=cfg["view_matching"]["within_shot"],
                                   seed=cfg["seed"], num_threads=sm.threads, work_dir=work,
                                   use_gpu=use_gpu))
    (work / "database.db").replace(out_db)
finally:
    shutil.rmtree(work, ignore_errors=True)
write_json(sm.output.info, info)
