"""Rule convert: one lenslet image -> its measurements (plenocal.convert.analysis), its
central view, patch-size map and disparity range (plenocal.convert); rule convert_views
renders the other views from the measurements."""

import time

import cv2

from plenocal.convert import ConvertSettings, convert_files
from plenocal.convert.analysis import write_analysis
from plenocal.io.files import write_image, write_json, write_npy
from plenocal.names import parse_view
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
write_analysis(snakemake.output.analysis, shot.analysis)
r, c = parse_view(snakemake.params.centre)
write_image(snakemake.output.centre, shot.view(r, c))
log.info("%s: central view %s written", cam, snakemake.params.centre)
write_json(snakemake.output.disparity, stats)
log.info("%s: D_min %.4f, D_max %.4f px (paper sign), %.2f s in all", cam, stats["D_min"],
         stats["D_max"], time.perf_counter() - t0)
