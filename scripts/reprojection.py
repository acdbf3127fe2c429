"""Rules reprojection_calib and reprojection: the reprojection error of one calibration
(Table I of the paper), and the table of all of them."""
import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.artifacts.results import ReprojectionTable, write_reprojection_table
from plenocal.io.files import read_json, write_json
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
    write_json(sm.output[0], rp.evaluate_calibration(sm.wildcards.calib, sm.input.calib,
                                                     sm.input.database, sm.params.central,
                                                     **opts))
