"""Rule scale: Eq. 5 on the central views' depth maps of registrations A and B."""

import logging

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.io import write_json
from plenocal.scale import scale_from_files

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
log = logging.getLogger("scale")

shots = list(snakemake.params.shots)
pairs = dict(zip(shots, zip(snakemake.input.depth_a, snakemake.input.depth_b, strict=True),
                 strict=True))
cfg = snakemake.params.scale
out = scale_from_files(pairs, float(cfg["low_percentile"]), float(cfg["high_percentile"]),
                       log=log.info)
log.info("r = %.6g (median %.6g, median of ratios %.6g), relative spread %.3g",
         out["r"], out["r_median"], out["r_median_of_ratios"], out["spread"]["relative"])
out["estimator"] = cfg.get("estimator", "mean")
out["r_used"] = {"mean": out["r"], "median": out["r_median"],
                 "median_of_ratios": out["r_median_of_ratios"]}[out["estimator"]]
write_json(snakemake.output.scale, out)
