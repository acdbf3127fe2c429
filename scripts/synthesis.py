"""Rules synthesis_exp1..3: one view-synthesis experiment of Fig. 6 on the complete
calibration and, on synthetic data, on the ground-truth cameras (the dB lost to
calibration). See plenocal.synthesis."""

import logging
import time
from pathlib import Path

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.camera import read_cameras
from plenocal.depth.inputs import rig_bounds
from plenocal.io import read_json, to_uint8, write_image, write_json
from plenocal.synthesis import (
    SynthesisContext,
    experiment1,
    experiment2,
    experiment3,
    layout_from_cams,
    lost_db,
)

snakemake = globals()["snakemake"]
logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True,
                    format="%(asctime)s %(levelname)s %(message)s")
log = logging.getLogger("synthesis")

exp = int(snakemake.params.experiment)
cfg = dict(snakemake.params.verify)
cfg["depth"] = dict(snakemake.params.depth)
views_dir = Path(snakemake.params.views_dir)
layout = layout_from_cams(list(snakemake.params.array_cams), int(snakemake.params.n_views))
near, far = rig_bounds(read_json(snakemake.input.rig), float(cfg["depth"].get("bounds_margin",
                                                                              0.15)))
calibs = {"complete": snakemake.input.calibration}
if snakemake.input.get("truth"):
    calibs["ground_truth"] = snakemake.input.truth

out = {"experiment": exp, "near_m": near, "far_m": far,
       "psnr_border_px": int(cfg.get("psnr_border_px", 8)), "calibrations": {}}
synth_dir = Path(snakemake.output.synth)
for name, path in calibs.items():
    t0 = time.perf_counter()
    ctx = SynthesisContext(read_cameras(path),
                           lambda cam, view: str(views_dir / cam / f"{view}.png"),
                           layout, near, far, cfg)
    if exp == 1:
        res, kept = experiment1(ctx)
    elif exp == 2:
        sets = [layout.middle_cam] if cfg.get("exp2_sets", "middle") == "middle" else layout.cams
        res, kept = experiment2(ctx, sets)
    else:
        res, kept = experiment3(ctx, int(cfg.get("exp3_view_stride", 1)))
    res["seconds"] = round(time.perf_counter() - t0, 1)
    out["calibrations"][name] = res
    log.info("%s: experiment %d done in %.1f s", name, exp, res["seconds"])
    for key, img in sorted(kept.items()):
        write_image(synth_dir / f"{name}_{key.replace('/', '_').replace(':', '_')}.png",
                    to_uint8(img))

if "ground_truth" in out["calibrations"]:
    c, g = out["calibrations"]["complete"], out["calibrations"]["ground_truth"]
    if exp == 3:
        out["db_lost"] = {v: lost_db(c[v], g[v]) for v in ("central", "lateral")}
    else:
        out["db_lost"] = lost_db(c, g)
synth_dir.mkdir(parents=True, exist_ok=True)
write_json(snakemake.output.json, out)
