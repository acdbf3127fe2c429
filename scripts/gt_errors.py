"""Rule gt_errors: every calibration stage against the simulator's ground truth
(synthetic datasets only; see plenocal.verify.gt_errors for what is compared)."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.reg_a import read_reg_a
from plenocal.artifacts.results import GroundTruthErrors, write_gt_errors
from plenocal.artifacts.rig import read_rig
from plenocal.artifacts.scale import read_scale
from plenocal.calib.reg_a.uncertainty import focal_std_px
from plenocal.io.files import read_json
from plenocal.rulelog import rule_logger
from plenocal.verify.error_sources import error_sources
from plenocal.verify.gt_errors import complete_errors, gt_errors, refine_errors

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "gt_errors")

truth = read_cameras(snakemake.input.truth)
log.info("ground truth: %d cameras from %s", len(truth), snakemake.input.truth)
scale = read_scale(snakemake.input.scale)
r = scale.r_used
reg_a = read_reg_a(snakemake.input.reg_a)
rig = read_rig(snakemake.input.rig)
out = gt_errors(truth, reg_a=reg_a, rig=rig.doc, r=r,
                calib=read_cameras(snakemake.input.calibration))
out["scale"]["r_mean_err_pct"] = 100.0 * (scale.r / out["scale"]["r_truth"] - 1.0)
out["scale"]["r_median_err_pct"] = 100.0 * (scale.r_median / out["scale"]["r_truth"] - 1.0)
out["scale"]["source"] = scale.chosen
out["scale"]["r_eq5_err_pct"] = 100.0 * (scale.r_eq5 / out["scale"]["r_truth"] - 1.0)
if scale.r_array_step is not None:
    out["scale"]["r_array_step_err_pct"] = 100.0 * (scale.r_array_step
                                                    / out["scale"]["r_truth"] - 1.0)
refine = read_json(snakemake.input.refine)
if refine.get("enabled"):
    # the paper's Eq. 6 result beside the refined one, and the refinement's own scale
    out["eq6"] = complete_errors(read_cameras(snakemake.input.eq6), truth)
    out["refinement"] = refine_errors(refine, r, out["scale"]["r_truth"])
# map_a writes it into reg_a.json; a reg_a.json from before that has none: from the model
sigma = (reg_a.stats["focal_std_px"] if "focal_std_px" in reg_a.stats
         else focal_std_px(snakemake.input.model))
out["sources"] = error_sources(truth, reg_a, {v: M for v, (_, M) in rig.view_poses().items()},
                               r, out, focal_std_px=sigma, scale_source=scale.chosen)
s_ = out["sources"]
log.info("error sources: A focal %+.4f %% (std %s %%), only A poses %.4f mm, only scale "
         "%.4f mm, only rig %.4f mm: dominant %s", s_["a_focal_pct"],
         "-" if s_["a_focal_std_pct"] is None else f"{s_['a_focal_std_pct']:.3f}",
         s_["only_a_poses_mm"], s_["only_scale_mm"], s_["only_rig_mm"], s_["dominant"])
for c in out["checks"]:
    v = "n/a" if c["value"] is None else f"{c['value']:.4g}"
    log.info("%-18s %10s %-10s target %-5g %s", c["name"], v, c["unit"], c["target"],
             {True: "pass", False: "FAIL", None: "-"}[c["pass"]])
write_gt_errors(snakemake.output.errors, GroundTruthErrors.from_dict(out))
