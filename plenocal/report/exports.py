"""The calibration's files for other tools, as the report lists them (section "Calibration
files for other tools") and rule report asks for them (``rules/common.smk``,
``report_inputs``). A module of its own, importing nothing, because the workflow reads it
at every start (the no-op's time)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Export:
    """One file or folder of the calibration written for another tool."""

    rel: str  # under results/<dataset>/
    rule: str  # the rule that writes it
    tools: str  # who reads it
    holds: str  # what it holds, in words
    #: made only where the run's targets ask for it (a switch in the config, or the rules
    #: that make its inputs: rules/common.smk, ``optional_export_targets``), not by every
    #: run that has its rule
    optional: bool = False


#: the calibration's exports, as the README's "Outputs" lists them, in the order a user looks
#: for them; the report lists those its run made (rule report's ``exports`` input)
EXPORTS: tuple[Export, ...] = (
    Export("calibration/cameras.json", "refine", "Python (plenocal.artifacts.cameras), "
           "scripts", "every view's K and camera-to-world, OpenCV axes, metres"),
    Export("calibration/mpeg/cameras.json", "refine", "RVS, DERS/IVDE, TMIV",
           "MPEG-I camera JSON (OMAF axes)"),
    Export("calibration/mpeg/rvs", "mpeg_views", "RVS",
           "one configuration per synthesis experiment, its inputs' depth maps and textures "
           "in mpeg/depth/ and mpeg/texture/", optional=True),
    Export("calibration/colmap", "refine", "COLMAP, NeRF tools that read poses",
           "a sparse model: every view's intrinsics and pose, no points; images: views/"),
    Export("calibration/colmap_points", "reprojection_complete",
           "nerfstudio (splatfacto), gsplat",
           "the same cameras with Table I's triangulated points, coloured, filtered at "
           "COLMAP's 4 px; images: views/"),
    Export("calibration/gaussian_splatting", "gaussian_splatting",
           "3D Gaussian splatting (graphdeco-inria)",
           "images/ cropped about each view's principal point, and sparse/0/",
           optional=True),
    Export("calibration/eq6/cameras.json", "merge", "comparison with the paper",
           "the paper's Eq. 6 result; the same formats in eq6/mpeg/ and eq6/colmap/"),
)
