"""Rules reprojection_calib and reprojection: the reprojection error of one calibration
(Table I of the paper), and the table of all of them."""
import logging

import cv2  # noqa: F401  (before pycolmap: DESIGN.md, Known traps)

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.results import ReprojectionTable, write_reprojection_table
from plenocal.artifacts.rig import read_rig
from plenocal.camera import read_cameras
from plenocal.io.files import read_json, write_json
from plenocal.rulelog import log_to_file
from plenocal.verify import reprojection as rp

log_to_file(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821

if sm.rule == "reprojection":
    doc = {k: read_json(p) for k, p in zip(sm.params.calibs, sm.input.evals, strict=True)}
    base = read_json(sm.input.baseline)
    if sm.input.scratch:
        s = read_json(sm.input.scratch[0])
        doc["sfm_scratch"] = {"num_images": s["num_images"],
                              "num_registered": s["registered_largest_model"],
                              "num_models": s["num_models"],
                              "focal_px": s.get("focal_px")}
    doc["baseline_sfm"]["num_registered"] = base["a_sfm_registered"]
    for name, row in doc.items():
        logging.info("Table I %-13s images %4s  mean %s px  median %s px", name,
                     row.get("num_images"), row.get("mean_px"), row.get("median_px"))
    write_reprojection_table(sm.output[0], ReprojectionTable(doc))
else:
    cfg = sm.params.sfm
    opts = dict(max_error_px=cfg["reprojection"]["max_error_px"],
                min_angle_deg=cfg["reprojection"]["min_angle_deg"],
                track_error_px=cfg["reprojection"]["track_error_px"], seed=cfg["seed"],
                num_threads=sm.threads)
    db = sm.input.database
    calib = sm.wildcards.calib
    logging.info("reprojection of %s on the view database %s", calib, db)
    if calib == "reg_a":
        out = rp.evaluate(rp.reg_a_views(read_reg_a(sm.input.calib), sm.params.central), db,
                          **opts)
    elif calib == "reg_b":
        out = rp.evaluate_sets(read_rig(sm.input.calib), db, **opts)
    else:
        out = rp.evaluate(read_cameras(sm.input.calib), db, **opts)
    out["calibration"] = calib
    write_json(sm.output[0], out)
