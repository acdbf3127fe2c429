"""Rule merge: Eq. 6 for every view of every shot, written in every export format."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.cameras import write_cameras
from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import read_rig
from plenocal.artifacts.scale import read_scale
from plenocal.calib.merge import merge_registrations
from plenocal.export.colmap_model import write_colmap
from plenocal.export.mpeg import write_mpeg
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "merge")

reg_a = read_reg_a(snakemake.input.reg_a)
rig = read_rig(snakemake.input.rig)
r = read_scale(snakemake.input.scale).r_used
shots = list(snakemake.params.shots)
cams = merge_registrations(reg_a, rig, r, shots, str(snakemake.input.reg_a),
                           str(snakemake.input.rig))
log.info("Eq. 6: %d shots x %d views = %d cameras, r = %.6g, model %s", len(shots),
         rig.n_views ** 2, len(cams), r, rig.model)
extra = {"source": "plenocal merge (Eq. 6)", "rig_model": rig.model, "scale_r": r}
write_cameras(snakemake.output.plain, cams, extra=extra)
log.info("wrote %s", snakemake.output.plain)
near, far = rig.depth_range_m
write_mpeg(snakemake.output.mpeg, cams, (near, far), content_name=snakemake.wildcards.dataset)
log.info("wrote %s (Depth_range %.4f-%.4f m)", snakemake.output.mpeg, near, far)
write_colmap(snakemake.output.colmap, cams)
log.info("wrote %s", snakemake.output.colmap)
