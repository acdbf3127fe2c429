"""Rules view_features_<k>: SIFT of the subaperture views of a run of shots, one part of
the view database per shot (plenocal.calib.reg_a.viewdb); needs no calibration."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.calib.reg_a import viewdb
from plenocal.calib.reg_a.colmap import resolve_sfm_device
from plenocal.convert.viewset import view_set_files
from plenocal.io.files import make_temp_dir
from plenocal.malloc import keep_freed_memory
from plenocal.names import split_key
from plenocal.rulelog import log_to_file

log_to_file(snakemake.log[0])  # noqa: F821
# SIFT's scale space per view, freed and allocated again: keep the heap (plenocal.malloc)
keep_freed_memory()
sm = snakemake  # noqa: F821
cfg = sm.params.sfm
use_gpu, extractor = resolve_sfm_device(cfg)  # sfm.device and sfm.sift
views = {k: str(p) for k, p in view_set_files(sm.input.view_sets).items()}
for out in sm.output:
    out_db = Path(out)
    cam = out_db.stem
    shot_views = {k: p for k, p in views.items() if split_key(k)[0] == cam}
    if not shot_views:
        raise RuntimeError(f"{out_db}: no views of shot {cam} among the job's inputs")
    out_db.parent.mkdir(parents=True, exist_ok=True)
    # the database moves into place only once complete; a killed job's temporary folder
    # is removed by the next run (make_temp_dir)
    work = make_temp_dir(out_db.parent, f".{out_db.stem}.")
    try:
        viewdb.extract_view_features(shot_views, work / "features.db", work,
                                     max_num_features=cfg["max_num_features"],
                                     seed=cfg["seed"], extractor=extractor,
                                     num_threads=sm.threads, use_gpu=use_gpu)
        (work / "features.db").replace(out_db)
    finally:
        shutil.rmtree(work, ignore_errors=True)
