"""Rule depth: z-depth of the central view of one shot in registrations A and B
(plenocal.depth.shot)."""

import cv2  # (first: see DESIGN.md on cv2/pycolmap)

from plenocal.depth.inputs import preview
from plenocal.depth.shot import shot_depths
from plenocal.io.files import write_image, write_json, write_npy
from plenocal.rulelog import log_to_file

snakemake = globals()["snakemake"]
log_to_file(snakemake.log[0])
cv2.setNumThreads(max(1, int(snakemake.threads)))  # the job's cores only

out = snakemake.output
maps = shot_depths(snakemake.wildcards.cam, snakemake.params.centre, snakemake.input.reg_a,
                   snakemake.input.rig, snakemake.params.views_dir, snakemake.params.model_dir,
                   dict(snakemake.params.depth))
for reg, m in maps.items():
    write_npy(out[f"depth_{reg}"], m.depth)
    write_image(out[f"preview_{reg}"], preview(m.depth))
    write_json(out[f"info_{reg}"], m.info)
