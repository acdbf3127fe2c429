"""Rule rig_b: registration B (Section II-C) -> rig.json."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.disparity import read_disparity
from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import write_rig
from plenocal.calib.reg_b.datasheet import read_datasheet
from plenocal.calib.reg_b.rig import build_rig
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "rig_b")

params = snakemake.params
ds = read_datasheet(snakemake.input.camera)
shots = list(params.shots)
convs = []
for cam, path in zip(shots, snakemake.input.disparity, strict=True):
    c = read_disparity(path)
    log.info("%s: D_min %.4f, D_max %.4f px (paper sign), q %.4f px", cam, c.d_min, c.d_max, c.q)
    convs.append(c)
F_m = read_reg_a(snakemake.input.reg_a).focal_px
log.info("registration A focal length F_m = %.4f px", F_m)
rig = params.rig
doc = build_rig(ds, convs, F_m, int(params.views), model=rig["model"],
                tolerance=float(rig["check_tolerance"]), shot_names=shots)
sym, ex = doc["symbols"], doc["exact"]
log.info("paper: P %.6g mm, F %.4f mm, B %.5f mm, alpha %.6g rad, X_c %.2f mm, X_n %.1f, "
         "X_f %.1f mm", sym["P"], sym["F"], sym["B"], sym["alpha"], sym["X_c"], sym["X_n"],
         sym["X_f"])
log.info("exact: L %.4f mm, F %.4f mm, Z0 %.2f mm, B %.5f mm, pp shift %.4f px/step",
         ex["L"], ex["F_true"], ex["Z0"], ex["B"], ex["pp_shift_px"])
for name in ("paper", "exact"):
    ck = doc[name]["check"]
    log.info("Eqs. 2-3 check of the %s model: %s %s", name, ck.get("verdict"),
             {k: ck[k] for k in ("rel_diff_B", "rel_diff_alpha") if k in ck})
write_rig(snakemake.output.rig, doc)
log.info("wrote %s (model %s)", snakemake.output.rig, doc["model"])
