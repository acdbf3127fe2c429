"""How well registration A's own data fix its focal length: the standard deviation that
its bundle adjustment's covariance gives (COLMAP's ``estimate_ba_covariance``, the gauge
fixed by three points), scaled by the residuals' own spread.

A parallel array does not fix the focal length: it trades off against depth, exactly for
cameras that differ by translations in their image plane. Only the hand-held shots'
rotations and forward offsets break that, and with a narrow field of view weakly: a 10 deg
turn of a 500-px-wide view whose focal length is 0.5 % off moves the image's edges by a
few hundredths of a pixel once the turn itself is fitted. The covariance says how weak, per
capture (:mod:`plenocal.verify.error_sources`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def focal_std_px(model_dir: str | Path) -> float | None:
    """The standard deviation (pixels) of the shared focal length of the COLMAP model in
    ``model_dir`` (registration A's), or None where COLMAP cannot estimate it."""
    import pycolmap  # noqa: PLC0415

    return reconstruction_focal_std_px(pycolmap.Reconstruction(str(model_dir)))


def reconstruction_focal_std_px(rec) -> float | None:
    """:func:`focal_std_px` of a reconstruction in memory (``pycolmap.Reconstruction``
    with one shared camera; its values are read, not changed: the adjuster is built for
    the covariance and never solved)."""
    import pycolmap  # noqa: PLC0415

    if rec.num_cameras() != 1 or rec.num_reg_images() < 3:
        return None
    cfg = pycolmap.BundleAdjustmentConfig()
    for image_id in sorted(rec.reg_image_ids()):
        cfg.add_image(image_id)
    cfg.fix_gauge(pycolmap.BundleAdjustmentGauge.THREE_POINTS)
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = True
    opts.refine_principal_point = False
    opts.refine_extra_params = False
    adjuster = pycolmap.create_default_ceres_bundle_adjuster(opts, cfg, rec)
    cov = pycolmap.estimate_ba_covariance(pycolmap.BACovarianceOptions(), rec, adjuster)
    if cov is None:
        return None
    camera_id = next(iter(rec.cameras))
    c = cov.get_other_params_cov(rec.cameras[camera_id].params)
    if c is None:
        return None
    # the covariance is for unit noise per residual coordinate: scale by the residuals'
    errors = [rec.point3D(pid).error for pid in rec.point3D_ids()]
    if not errors:
        return None
    sigma = noise_per_coordinate_px(errors)
    var = float(np.asarray(c)[0, 0])
    return math.sqrt(var) * sigma if var > 0 else None


def noise_per_coordinate_px(errors_px) -> float:
    """The residuals' noise per image coordinate (px) that scales a covariance for unit
    noise: ``sqrt(mean(e^2) / 2)`` over reprojection errors ``e`` (each the length of a
    2-D residual); NaN for none."""
    e = np.asarray(errors_px, dtype=float)
    return float(np.sqrt(np.mean(np.square(e)) / 2.0)) if e.size else math.nan
