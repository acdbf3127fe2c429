"""Rule depth: z-depth of the central view of one shot in registration A (sources: the
central views of the nearest shots, SfM units) or B (sources: views of its own set,
metres). See plenocal.depth.inputs for the choices."""

import time
from pathlib import Path

import cv2  # (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import read_rig
from plenocal.depth import estimate_depth, resolve_backend
from plenocal.depth.inputs import (
    nearest_sources,
    preview,
    reg_a_bounds,
    rig_bounds,
)
from plenocal.io.files import read_image, write_image, write_json, write_npy
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "depth")
cv2.setNumThreads(max(1, int(snakemake.threads)))  # the job's cores only

cfg = dict(snakemake.params.depth)
reg = snakemake.wildcards.reg
cam = snakemake.wildcards.cam
centre = snakemake.params.centre
margin = float(cfg["bounds_margin"])
views_dir = Path(snakemake.params.views_dir)

if reg == "a":
    reg_a = read_reg_a(snakemake.input.reg_a)
    cameras = reg_a.cameras
    if cam not in cameras:
        raise ValueError(f"depth: shot {cam} is not registered in {snakemake.input.reg_a}; "
                         "look at the registration A log for why")
    near, far = reg_a_bounds(reg_a, cam, snakemake.params.model_dir, margin)
    srcs = nearest_sources(cam, cameras, int(cfg["sources_a"]))
    ref_cam, src_cams = cameras[cam], [cameras[s] for s in srcs]
    ref_path = views_dir / cam / f"{centre}.png"
    src_paths = [views_dir / s / f"{centre}.png" for s in srcs]
    units = "sfm"
else:
    rig = read_rig(snakemake.input.rig)
    cameras = rig.cameras()
    near, far = rig_bounds(rig, margin)
    srcs = nearest_sources(centre, cameras, cfg["sources_b"])
    ref_cam, src_cams = cameras[centre], [cameras[s] for s in srcs]
    ref_path = views_dir / cam / f"{centre}.png"
    src_paths = [views_dir / cam / f"{s}.png" for s in srcs]
    units = "m"

backend = resolve_backend(cfg["backend"])
log.info("%s/%s: backend %s, bounds [%.6g, %.6g] %s, sources %s", reg, cam, backend, near,
         far, units, ", ".join(srcs))
t0 = time.perf_counter()
depth = estimate_depth(ref_cam, read_image(ref_path), src_cams,
                       [read_image(p) for p in src_paths], near, far, cfg, backend=backend)
valid = float((depth > 0).mean())
log.info("%s/%s: %.1f s, %.1f %% valid", reg, cam, time.perf_counter() - t0, 100 * valid)
write_npy(snakemake.output.depth, depth)
write_image(snakemake.output.preview, preview(depth))
write_json(snakemake.output.info, {"backend": backend, "near": near, "far": far, "units": units,
                                   "sources": srcs, "valid_share": valid,
                                   "reference": f"{cam}/{centre}"})
