"""Rule depth: z-depth of the central view of one shot in registration A (sources: the
central views of the nearest shots, SfM units) or B (sources: views of its own set,
metres). See plenocal.depth.inputs for the choices."""

import time
from pathlib import Path

import cv2  # (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import read_rig
from plenocal.depth import estimate_depth, resolve_backend
from plenocal.depth.inputs import depth_job_a, depth_job_b, preview
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
    job = depth_job_a(read_reg_a(snakemake.input.reg_a), snakemake.input.reg_a, cam, centre,
                      views_dir, snakemake.params.model_dir, int(cfg["sources_a"]), margin)
else:
    job = depth_job_b(read_rig(snakemake.input.rig), cam, centre, views_dir, cfg["sources_b"],
                      margin)
near, far, units, srcs = job.near, job.far, job.units, job.src_names

backend = resolve_backend(cfg["backend"])
log.info("%s/%s: backend %s, bounds [%.6g, %.6g] %s, sources %s", reg, cam, backend, near,
         far, units, ", ".join(srcs))
t0 = time.perf_counter()
depth = estimate_depth(job.ref_cam, read_image(job.ref_path), job.src_cams,
                       [read_image(p) for p in job.src_paths], near, far, cfg, backend=backend)
valid = float((depth > 0).mean())
log.info("%s/%s: %.1f s, %.1f %% valid", reg, cam, time.perf_counter() - t0, 100 * valid)
write_npy(snakemake.output.depth, depth)
write_image(snakemake.output.preview, preview(depth))
write_json(snakemake.output.info, {"backend": backend, "near": near, "far": far, "units": units,
                                   "sources": srcs, "valid_share": valid,
                                   "reference": f"{cam}/{centre}"})
