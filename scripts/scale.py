"""Rule scale: Eq. 5 on the central views' depth maps of registrations A and B."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.scale import write_scale
from plenocal.calib.scale import estimate_scale
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "scale")

shots = list(snakemake.params.shots)
pairs = dict(zip(shots, zip(snakemake.input.depth_a, snakemake.input.depth_b, strict=True),
                 strict=True))
cfg = snakemake.params.scale
result = estimate_scale(pairs, float(cfg["low_percentile"]), float(cfg["high_percentile"]),
                        cfg["estimator"], log=log.info)
log.info("r = %.6g (median %.6g, median of ratios %.6g), relative spread %.3g; the merge uses "
         "the %s: %.6g", result.r, result.r_median, result.r_median_of_ratios,
         result.spread["relative"], result.estimator, result.r_used)
write_scale(snakemake.output.scale, result)
