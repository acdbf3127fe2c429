"""Rule merge: Eq. 6 for every view of every shot, written in every export format."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.rig import read_rig
from plenocal.artifacts.scale import read_scale
from plenocal.calib.merge import merge_cameras
from plenocal.export.colmap_model import write_colmap
from plenocal.export.mpeg import write_mpeg
from plenocal.export.plain import write_plain
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "merge")

reg_a = read_reg_a(snakemake.input.reg_a)
rig = read_rig(snakemake.input.rig)
r = read_scale(snakemake.input.scale).r_used
shots = list(snakemake.params.shots)
missing = [c for c in shots if c not in reg_a.cameras]
if missing:
    raise ValueError(f"{snakemake.input.reg_a}: registration A has no pose for "
                     f"{', '.join(missing)}; rerun map_a or drop those shots")
if abs(reg_a.focal_px - rig.focal_px) > 1e-6 * reg_a.focal_px:
    raise ValueError(f"{snakemake.input.rig} was built with focal length {rig.focal_px} px, "
                     f"registration A now says {reg_a.focal_px} px: rerun rig_b")
poses = {c: reg_a.poses[c] for c in shots}
cams = merge_cameras(poses, rig.view_poses(), r, rig.width, rig.height)
log.info("Eq. 6: %d shots x %d views = %d cameras, r = %.6g, model %s", len(poses),
         rig.n_views ** 2, len(cams), r, rig.model)
extra = {"source": "plenocal merge (Eq. 6)", "rig_model": rig.model, "scale_r": r}
write_plain(snakemake.output.plain, cams, extra=extra)
log.info("wrote %s", snakemake.output.plain)
near, far = rig.depth_range_m
write_mpeg(snakemake.output.mpeg, cams, (near, far), content_name=snakemake.wildcards.dataset)
log.info("wrote %s (Depth_range %.4f-%.4f m)", snakemake.output.mpeg, near, far)
write_colmap(snakemake.output.colmap, cams)
log.info("wrote %s", snakemake.output.colmap)
