"""Rules depth_view and depth_view_truth: the dense z-depth map of one view for view
synthesis and the MPEG exports (SGM over the multi-view plane-sweep cost volume by
default), with the complete calibration, or with the ground-truth cameras for their own
synthesis runs. See plenocal.depth.views."""

import time
from pathlib import Path

import cv2  # (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.rig import read_rig
from plenocal.depth.inputs import preview, rig_bounds
from plenocal.depth.views import estimate_view_depth
from plenocal.io.files import read_image, write_image, write_json, write_npy
from plenocal.names import split_key
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "depth_view")
cv2.setNumThreads(max(1, int(snakemake.threads)))  # the job's cores only

cfg = dict(snakemake.params.depth)
verify = dict(snakemake.params.verify)
key = f"{snakemake.wildcards.cam}/{snakemake.wildcards.view}"
views_dir = Path(snakemake.params.views_dir)
cameras = read_cameras(snakemake.input.calibration)
near, far = rig_bounds(read_rig(snakemake.input.rig), float(cfg["bounds_margin"]))
images = {}


def image(k):
    if k not in images:
        cam, view = split_key(k)
        images[k] = read_image(views_dir / cam / f"{view}.png")
    return images[k]


t0 = time.perf_counter()
depth, srcs = estimate_view_depth(key, cameras, image, near, far, int(snakemake.params.n_views),
                                  cfg, int(verify["depth_sources_shots"]),
                                  int(verify["depth_sources_set"]))
valid = float((depth > 0).mean())
log.info("%s: %s, %.1f s, %.1f %% valid, sources %s", key, cfg["synthesis_method"],
         time.perf_counter() - t0, 100 * valid, ", ".join(srcs))
write_npy(snakemake.output.depth, depth)
write_image(snakemake.output.preview, preview(depth))
write_json(snakemake.output.info, {"method": cfg["synthesis_method"], "near": near,
                                   "far": far, "units": "m", "sources": srcs,
                                   "valid_share": valid, "view": key,
                                   "calibration": str(snakemake.params.cameras)})
