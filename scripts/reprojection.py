"""Rules reprojection_calib, reprojection_complete and reprojection: the reprojection error
of one calibration (Table I of the paper; the complete calibration's triangulation also
written as a COLMAP model with its points), and the table of all of them."""
import shutil
from pathlib import Path

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.artifacts.results import ReprojectionTable, write_reprojection_table
from plenocal.convert.viewset import view_set_files
from plenocal.io.files import make_temp_dir, read_json, write_json
from plenocal.rulelog import log_to_file
from plenocal.verify import reprojection as rp

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821

if sm.rule == "reprojection":
    evals = {k: read_json(p) for k, p in zip(sm.params.calibs, sm.input.evals, strict=True)}
    scratch = read_json(sm.input.scratch[0]) if sm.input.scratch else None
    write_reprojection_table(sm.output[0], ReprojectionTable(
        rp.table_i(evals, read_json(sm.input.baseline), scratch)))
else:
    cfg = sm.params.sfm
    opts = dict(max_error_px=cfg["reprojection"]["max_error_px"],
                min_angle_deg=cfg["reprojection"]["min_angle_deg"],
                track_error_px=cfg["reprojection"]["track_error_px"], seed=cfg["seed"],
                num_threads=sm.threads)
    # COLMAP's working files beside the output, not in $TMPDIR: removed at the end, and a
    # killed job's by the next run of the same calibration's job (make_temp_dir; the jobs of
    # the other calibrations, which may run alongside, have prefixes of their own)
    calib = "complete" if sm.rule == "reprojection_complete" else sm.wildcards.calib
    if calib == "complete":
        opts.update(model_dir=sm.output.model, images=view_set_files(sm.input.view_sets))
    work = make_temp_dir(Path(sm.output[0]).parent, f".{calib}.")
    try:
        row = rp.evaluate_calibration(calib, sm.input.calib, sm.input.database,
                                      sm.params.central, work_dir=work, **opts)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    write_json(sm.output[0], row)
