"""Rule scale: Eq. 5 on the central views' depth maps of registrations A and B, and the
scale that the stage's step gives (camera.yaml, array.step_mm) beside it."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.scale import write_scale
from plenocal.calib.reg_b.datasheet import read_datasheet
from plenocal.calib.scale import estimate_scale
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "scale")

shots = list(snakemake.params.shots)
pairs = dict(zip(shots, zip(snakemake.input.depth_a, snakemake.input.depth_b, strict=True),
                 strict=True))
cfg = snakemake.params.scale
step_mm = read_datasheet(snakemake.input.camera).array_step
reg_a = read_reg_a(snakemake.input.reg_a)
result = estimate_scale(pairs, float(cfg["low_percentile"]), float(cfg["high_percentile"]),
                        cfg["estimator"], log=log.info, reference=cfg["reference"],
                        array_poses=reg_a.poses,
                        step_m=None if step_mm is None else step_mm / 1000.0)
log.info("Eq. 5: r = %.6g (median %.6g, median of ratios %.6g), relative spread %.3g",
         result.r, result.r_median, result.r_median_of_ratios, result.spread["relative"])
if result.r_array_step is not None:
    st = result.array_step
    log.info("the stage's step %.4g mm over A's array spacing %.6g: r = %.6g (%+.3f %% from "
             "Eq. 5's %s), lattice fit RMS %.2f %% of the step", 1000 * st["step_m"],
             st["spacing_sfm"], result.r_array_step, 100 * (result.r_array_step / result.r_eq5
                                                           - 1), result.estimator,
             st["fit_rms_pct_of_step"])
for w in result.warnings:
    log.warning(w)
log.info("the merge uses %s: r = %.6g", "the stage's step" if result.chosen == "array_step"
         else f"Eq. 5's {result.estimator}", result.r_used)
write_scale(snakemake.output.scale, result)
