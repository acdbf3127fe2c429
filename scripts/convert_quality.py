"""Rule convert_quality: PSNR/SSIM of every converted view against the simulator's ideal
renders (synthetic datasets)."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.results import ConvertQuality, write_convert_quality
from plenocal.convert.quality import dataset_quality
from plenocal.convert.setup import read_setup
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "convert_quality")

pairs = []
for truth in snakemake.input.truth:
    t = Path(truth)
    cam, view = t.parent.name, t.stem
    pairs.append((cam, view, Path(snakemake.params.views_dir) / cam / f"{view}.png", t))
result = dataset_quality(pairs, border=read_setup(snakemake.input.setup).tile,
                         central=snakemake.params.central)
for cam, views in result["per_view"].items():
    for view, q in views.items():
        log.info("%s/%s: PSNR %.2f dB, SSIM %.4f", cam, view, q["psnr_db"], q["ssim"])
log.info("mean PSNR of central views %.2f dB, min %.2f dB (%s); targets met: %s",
         result["mean_psnr_central_db"] or float("nan"), result["min_psnr_db"] or float("nan"),
         result["worst_view"], result["meets_targets"])
write_convert_quality(snakemake.output.quality, ConvertQuality.from_dict(result))
