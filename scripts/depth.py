"""Rules depth_a and depth_b: z-depth of the central view of every shot in registration A
or B (plenocal.depth.shot)."""

from pathlib import Path

import cv2  # (first: see DESIGN.md on cv2/pycolmap)

from plenocal.depth.inputs import preview
from plenocal.depth.shot import depths_a, depths_b
from plenocal.io.files import write_image, write_json, write_npy
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
params = snakemake.params
log = rule_logger(snakemake, f"depth_{params.registration}")
threads = max(1, int(snakemake.threads))

cams = list(params.cams)
cfg = dict(params.depth)
if params.registration == "a":
    cv2.setNumThreads(1)  # the job's cores sweep a map each (processes)
    maps = depths_a(cams, params.centre, snakemake.input.reg_a, params.views_dir,
                    params.model_dir, cfg, progress=log.info, threads=threads)
else:
    cv2.setNumThreads(threads)  # the job's cores only
    maps = depths_b(cams, params.centre, snakemake.input.rig, params.views_dir, cfg,
                    progress=log.info)
out = snakemake.output
for paths in zip(out.depth, out.preview, out.info, strict=True):
    cam = Path(paths[0]).stem
    if any(Path(p).stem != cam for p in paths) or cam not in maps:
        raise RuntimeError(f"{paths}: outputs out of step with the shots {cams}")
    write_npy(paths[0], maps[cam].depth)
    write_image(paths[1], preview(maps[cam].depth))
    write_json(paths[2], maps[cam].info)
