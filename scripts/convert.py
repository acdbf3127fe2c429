"""Rules convert_<k>: the lenslet images of a run of shots -> per shot its measurements
(plenocal.convert.analysis), central view, patch-size map and disparity range
(plenocal.convert); rules convert_views_<k> render the other views from the measurements."""

import time
from pathlib import Path

import cv2

from plenocal.convert import ConvertSettings, convert_files
from plenocal.convert.analysis import write_analysis
from plenocal.convert.video import video_settings
from plenocal.io.files import write_image, write_json, write_npy
from plenocal.names import parse_view
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "convert")
cv2.setNumThreads(max(1, int(snakemake.threads)))

params = snakemake.params
inp, out = snakemake.input, snakemake.output
settings = ConvertSettings.from_config(params.convert)
# shots given as a video: rule lenslet_frame's frames (16-bit, or 8-bit from an 8-bit
# recording; common.smk convert_settings)
frames = set(params.convert.get("video_frames", ()))
n_views = int(params.views)
r, c = parse_view(params.centre)
for k, cam in enumerate(params.cams):
    t0 = time.perf_counter()
    shot = convert_files(inp.lenslet[k], inp.calib, inp.camera, n_views,
                         video_settings(settings) if cam in frames else settings,
                         setup_json=inp.setup, threads=max(1, int(snakemake.threads)))
    stats = shot.disparity()
    log.info("%s: %d lenses (%d used), patch size %.2f..%.2f px (median %.2f, %.0f%% "
             "confident), %.2f s", cam, len(shot.grid), stats["used_lenses"],
             stats["patch_size_px"]["min"], stats["patch_size_px"]["max"],
             stats["patch_size_px"]["median"], 100 * stats["patch_size_px"]["confident_share"],
             time.perf_counter() - t0)
    paths = (out.centre[k], out.analysis[k], out.patch_size[k], out.patch_png[k],
             out.disparity[k])
    if any(Path(p).parent.name != cam for p in paths):
        raise RuntimeError(f"{paths}: outputs out of step with the shots {params.cams}")
    write_npy(out.patch_size[k], shot.used_patch)
    write_image(out.patch_png[k], shot.patch_picture())
    write_analysis(out.analysis[k], shot.analysis)
    write_image(out.centre[k], shot.view(r, c))
    write_json(out.disparity[k], stats)
    log.info("%s: D_min %.4f, D_max %.4f px (paper sign), central view %s, %.2f s in all "
             "(%d of %d)", cam, stats["D_min"], stats["D_max"], params.centre,
             time.perf_counter() - t0, k + 1, len(params.cams))
