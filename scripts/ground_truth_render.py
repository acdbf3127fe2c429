"""Rule ground_truth_render: ideal pinhole render and z-depth of one view."""

import logging

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.camera import PinholeCamera
from plenocal.io import read_json, to_uint8, write_image, write_npy
from plenocal.simulate.raytrace import render_pinhole
from plenocal.simulate.scene import scene_arrays

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
wc = snakemake.wildcards
cams = read_json(snakemake.input.cams)["cameras"]
cam = PinholeCamera.from_dict(cams[f"{wc.cam}/{wc.view}"])
scene_json = [p for p in snakemake.input if p.endswith("scene.json")][0]
scene = scene_arrays(read_json(scene_json))
img, depth = render_pinhole(scene, cam.K, cam.cam_to_world, cam.width, cam.height,
                            int(snakemake.params.supersample))
write_image(snakemake.output.image, to_uint8(img))
write_npy(snakemake.output.depth, depth)
logging.info("%s/%s: %dx%d, depth %.3f-%.3f m", wc.cam, wc.view, cam.width, cam.height,
             float(depth[depth > 0].min()), float(depth.max()))
