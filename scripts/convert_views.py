"""Rules convert_views_<k>: the views other than the central one of a run of shots, rendered
from each shot's measurements (rule convert's analysis.npz; plenocal.convert.analysis),
and each shot's views.json (plenocal.convert.viewset)."""

import time
from pathlib import Path

import cv2

from plenocal.convert import ConvertSettings, convert_files
from plenocal.convert.analysis import read_analysis
from plenocal.convert.video import video_settings
from plenocal.convert.viewset import remove_stale_views, view_set_path, write_view_set
from plenocal.io.files import write_images
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "convert_views")
threads = max(1, int(snakemake.threads))
cv2.setNumThreads(threads)

params = snakemake.params
settings = ConvertSettings.from_config(params.convert)
# shots given as a video: rule lenslet_frame's frames (16-bit, or 8-bit from an 8-bit
# recording; common.smk convert_settings)
frames = set(params.convert.get("video_frames", ()))
inp = snakemake.input
outputs = {str(p) for p in snakemake.output}
for k, (cam, lenslet, analysis) in enumerate(zip(params.cams, inp.lenslet, inp.analysis,
                                                  strict=True)):
    t0 = time.perf_counter()
    shot = convert_files(lenslet, inp.calib, inp.camera, int(params.views),
                         video_settings(settings) if cam in frames else settings,
                         setup_json=inp.setup, analysis=read_analysis(analysis),
                         threads=threads)
    out_dir = Path(analysis).parent
    # the views not on disk are declared outputs, the others are overwritten (atomically):
    # the consumers read them through views.json (rules/common.smk missing_views)
    for views in shot.view_groups(params.names, threads=threads):
        write_images(((out_dir / f"{name}.png", img) for name, img in views.items()), threads)
        views.clear()  # before the next group is rendered
    # the shot's views as one unit, central view included: what the rules that read
    # whole shots take as their input (plenocal.convert.viewset)
    if str(view_set_path(out_dir)) not in outputs:
        raise RuntimeError(f"{view_set_path(out_dir)} is not a declared output of "
                           f"{snakemake.rule}")
    write_view_set(out_dir, params.all_names)
    stale = remove_stale_views(out_dir, params.all_names)
    if stale:
        log.info("%s: removed %d views of an earlier views setting (%s ... %s)", cam,
                 len(stale), stale[0].name, stale[-1].name)
    log.info("%s: %d views in %.2f s (%d of %d)", cam, len(params.names),
             time.perf_counter() - t0, k + 1, len(params.cams))
