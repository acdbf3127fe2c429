"""Rule convert: one lenslet image -> its N x N subaperture views, patch-size map and
disparity range (plenocal.convert)."""

import time
from pathlib import Path

import cv2

from plenocal.convert import ConvertSettings, convert_files
from plenocal.io.files import write_image, write_json, write_npy
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "convert")
cv2.setNumThreads(max(1, int(snakemake.threads)))

cam = snakemake.wildcards.cam
settings = ConvertSettings.from_config(snakemake.params.convert)
n_views = int(snakemake.params.views)
t0 = time.perf_counter()
shot = convert_files(snakemake.input.lenslet, snakemake.input.calib, snakemake.input.camera,
                     n_views, settings, setup_json=snakemake.input.setup)
stats = shot.disparity()
log.info("%s: %d lenses (%d used), patch size %.2f..%.2f px (median %.2f, %.0f%% confident), "
         "%.2f s", cam, len(shot.grid), stats["used_lenses"], stats["patch_size_px"]["min"],
         stats["patch_size_px"]["max"], stats["patch_size_px"]["median"],
         100 * stats["patch_size_px"]["confident_share"], time.perf_counter() - t0)
write_npy(snakemake.output.patch_size, shot.used_patch)
write_image(snakemake.output.patch_png, shot.patch_picture())
out_dir = Path(snakemake.output.disparity).parent
expected = {str(p) for p in snakemake.output.views}
for name, img in shot.views():
    path = out_dir / f"{name}.png"
    if str(path) not in expected:
        raise RuntimeError(f"{path} is not a declared output of rule convert")
    write_image(path, img)
    log.info("%s: view %s written (%dx%d)", cam, name, img.shape[1], img.shape[0])
write_json(snakemake.output.disparity, stats)
log.info("%s: D_min %.4f, D_max %.4f px (paper sign), %.2f s in all", cam, stats["D_min"],
         stats["D_max"], time.perf_counter() - t0)
