"""Rule mpeg_views: the depth maps (16-bit normalised disparity, YUV 4:2:0 and PNG),
the textures (YUV 4:2:0) and one RVS configuration per view-synthesis experiment
beside calibration/mpeg/cameras.json. See plenocal.export.mpeg_views."""

from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.convert.viewset import view_set_files
from plenocal.export.mpeg_views import export_views
from plenocal.io.files import read_image, read_npy
from plenocal.names import file_key
from plenocal.rulelog import rule_logger
from plenocal.verify.experiments import experiment_plan, layout_from_cams

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "mpeg_views")

verify = dict(snakemake.params.verify)
layout = layout_from_cams(list(snakemake.params.array_cams), int(snakemake.params.n_views))
depth_files = {file_key(p): p for p in snakemake.input.depth}
view_files = view_set_files(snakemake.input.view_sets)
sets = layout.exp2_cams(verify["exp2_sets"])
plans = {}
for exp in (1, 2, 3):
    plans.update(experiment_plan(layout, exp, sets, int(verify["exp3_view_stride"])))
out_dir = Path(snakemake.input.mpeg).parent
written = export_views(out_dir, snakemake.input.mpeg, sorted(depth_files),
                       lambda k: read_npy(depth_files[k]), lambda k: read_image(view_files[k]),
                       plans, float(verify["rvs_blending_factor"]))
for name in ("depth", "texture", "rvs"):
    (out_dir / name).mkdir(parents=True, exist_ok=True)
log.info("wrote %d files under %s: %s", len(written), out_dir, ", ".join(plans))
