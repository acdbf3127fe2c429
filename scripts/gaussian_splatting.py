"""Rule gaussian_splatting: calibration/gaussian_splatting/, every view cropped about its
principal point and named <shot>_<r>_<c>.png, with the COLMAP model of
calibration/colmap_points moved with the crops (plenocal.export.gaussian_splatting)."""

import cv2  # noqa: F401  (first: see DESIGN.md on cv2/pycolmap)

from plenocal.convert.viewset import view_set_files
from plenocal.export.gaussian_splatting import export_gaussian_splatting
from plenocal.io.files import read_image, write_image
from plenocal.rulelog import rule_logger

snakemake = globals()["snakemake"]
log = rule_logger(snakemake, "gaussian_splatting")
views = view_set_files(snakemake.input.view_sets)


def read_view(key: str):
    if key not in views:
        raise FileNotFoundError(f"{snakemake.input.model}: image {key}.png is in no view set "
                                f"of this run ({len(views)} views): run the calibration "
                                "again (snakemake --forcerun reprojection_complete)")
    return read_image(views[key])


info = export_gaussian_splatting(snakemake.input.model, snakemake.output[0], read_view,
                                 write_image,
                                 progress=lambda done, n: log.info("%d/%d views", done, n))
sizes = sorted({tuple(v["size"]) for v in info["views"].values()})
log.info("wrote %s: %d views, %d image sizes (%dx%d .. %dx%d)", snakemake.output[0],
         len(info["views"]), len(sizes), *sizes[0], *sizes[-1])
