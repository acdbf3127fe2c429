"""Rule ground_truth: gather the per-shot cameras into the plain cameras.json."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.io.files import read_json, write_json
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "ground_truth")
cameras, worst = {}, 0.0
for path in snakemake.input:
    doc = read_json(path)
    cameras.update(doc["cameras"])
    worst = max(worst, doc["fit_residual_px"])
write_json(snakemake.output[0], {"units": "m", "fit_residual_px": worst, "cameras": cameras})
log.info("%d ground-truth cameras, worst fit residual %.2e px", len(cameras), worst)
