"""How firmly the joint refinement's data fix the shared focal length (config
``refine.focal_sd``; beyond the paper): the standard deviation its focal pass's covariance
gives, as :mod:`plenocal.calib.reg_a.uncertainty` gives registration A's.

The focal pass (:func:`plenocal.calib.refine.bundle_adjust` with ``refine_focal``) frees
each sensor's focal length; the covariance of those parameters, with the shots' poses (the
rig's frames) and the points marginalised out (COLMAP's ``estimate_ba_covariance``: the
Schur complement on the points, then on the other parameters), is for unit noise per
residual coordinate and is scaled here by the residuals' own spread,

    sd(f) = sqrt(C_ff) * sigma,    sigma = sqrt(mean(e_i^2) / 2),

``e_i`` each observation's reprojection error (px), as registration A's estimate scales
its own (:func:`plenocal.calib.reg_a.uncertainty.noise_per_coordinate_px`). The sensors'
focal lengths are tied by the rig (they agree to 0.001-0.002 %, BENCHMARKS.md "The focal
length from every view"), so each one's standard deviation is the shared one's; the
median over the sensors is reported.

COLMAP 4.2's estimator takes an image's pose as the pose block by default and refuses a
rig's non-reference sensors (``image.IsRefInFrame()``); the frames' ``rig_from_world``
blocks are given to it instead (``BACovarianceOptions.experimental_custom_poses``).

The estimate holds the whole problem's Jacobian, so it is made on a thinned copy of the
reconstruction: every k-th point (:func:`points_every`: the smallest k that leaves at most
:data:`MAX_OBSERVATIONS` observations), its variance then scaled by the share of the
observations kept (``sd = sd_thinned * sqrt(kept / all)``: the variance of a mean of
independent clusters falls as their number). On three captures of the ``small``, default and
``dense`` geometries (seed 101) it gave the whole problem's deviation to within 0.004 % of
the focal length, 4 % of the figure: 0.0998 % whole against 0.1004 % on every second point
and 0.1035 % on every fourth (small); 0.0470 against 0.0487 % on every fifth (default, the
rule's k), 0.0472 and 0.0470 % on every fourth and eighth; 0.0447 against 0.0458 % on every
seventh (dense), 0.0447 and 0.0437 %. It took 0.7-1.6 s against 2.5-12.2 s, and the refine
job's peak memory stayed its own (1.33 GB on the default geometry with and without it,
1.78 GB with the whole problem; BENCHMARKS.md,
"The refined focal length's standard deviation on every run").

COLMAP's estimator sums in an order that moves the last bits of its result from run to run
(1e-11 of the value); the figures written are rounded to :data:`SIGNIFICANT` digits, so
that ``refine.json`` is the same bytes run after run.

Measured on 21 kept captures of five geometries (BENCHMARKS.md, "The refined focal
length's standard deviation"): the refined focal length's error against the truth over
this standard deviation has an RMS of 1.09, at most 2.24 (small-turned-s49); the estimate
is 0.08-0.14 % on the ``small`` geometry, 0.04-0.05 % on the default and Raytrix-like
ones. Held out (twelve captures of four geometries made after that, on another CPU):
RMS 0.95, at most 1.91, all within 2; thinned, on seeds 101-110 of thirteen
geometries (85 captures): RMS 0.89, at most 1.96, all within 2. Scaled by the median error
instead, it was 3-5x
too small: the tail that the Cauchy loss damps still carries the focal length's noise.
"""

from __future__ import annotations

import math
import time

import numpy as np

from plenocal.calib.reg_a.uncertainty import noise_per_coordinate_px
from plenocal.rounding import round_floats

#: the most observations the covariance is estimated on (module docstring)
MAX_OBSERVATIONS = 250_000
#: significant digits of the figures written (module docstring)
SIGNIFICANT = 4


def points_every(observations: int, most: int | None = None) -> int:
    """The smallest k such that every k-th point of a problem of ``observations``
    observations leaves at most about ``most`` of them (:data:`MAX_OBSERVATIONS` if None;
    1 where it holds no more)."""
    return max(1, math.ceil(observations / (MAX_OBSERVATIONS if most is None else most)))


def thinned(rec, every: int) -> tuple[object, int, int]:
    """A copy of ``rec`` (``pycolmap.Reconstruction``) holding every ``every``-th of its
    points (by id, the first kept), and the observations it and ``rec`` hold:
    ``(copy, kept, all)``. ``rec`` itself is not changed."""
    import pycolmap  # noqa: PLC0415

    out = pycolmap.Reconstruction(rec)
    for i, point_id in enumerate(sorted(out.point3D_ids())):
        if i % every:
            out.delete_point3D(point_id)
    return out, out.compute_num_observations(), rec.compute_num_observations()


def significant(x: float) -> float:
    """``x`` rounded to :data:`SIGNIFICANT` significant digits."""
    return round_floats(x, SIGNIFICANT)


def sensor_focal_std_pct(rec, camera_ids: list[int], pose_frames: list[int], *,
                         errors_px: np.ndarray, bundle_adjuster,
                         observations_share: float = 1.0) -> dict:
    """The focal lengths' standard deviation (%) of the sensors ``camera_ids`` of the rig
    reconstruction ``rec`` (``pycolmap.Reconstruction``) under the problem of
    ``bundle_adjuster`` (``pycolmap.CeresBundleAdjuster``, set up as the focal pass),
    the frames ``pose_frames`` (the variable ones) taken as its poses; ``errors_px`` the
    observations' reprojection errors. Returns the median over the sensors (``std_pct``),
    their range, the unit-noise figure (``per_px_noise_pct``), ``sigma_px`` and the
    seconds taken; ``std_pct`` None where COLMAP cannot estimate it. ``rec`` may be a
    thinned copy (:func:`thinned`) holding ``observations_share`` of the observations:
    the deviations are then scaled to the whole problem's, ``errors_px`` being the whole
    problem's."""
    import pycolmap  # noqa: PLC0415

    t0 = time.perf_counter()
    options = pycolmap.BACovarianceOptions()
    poses = []
    for frame_id in pose_frames:
        pose = pycolmap.ExperimentalPoseParam()
        pose.image_id = int(frame_id)
        # the frame's rotation block (its quaternion, the first four of the pose's
        # parameters, a view into the reconstruction: the problem's own block)
        pose.cam_from_world = rec.frames[frame_id].rig_from_world.params[:4]
        poses.append(pose)
    options.experimental_custom_poses = poses
    try:
        cov = pycolmap.estimate_ba_covariance(options, rec, bundle_adjuster)
    except (ValueError, RuntimeError) as err:
        # an estimate, not the calibration: a COLMAP that refuses it (the custom poses are
        # marked experimental) leaves the refinement as it is
        return {"std_pct": None, "why": f"COLMAP's covariance estimator: {err}",
                "seconds": time.perf_counter() - t0}
    sigma = noise_per_coordinate_px(errors_px)
    unit = []
    if cov is not None:
        for cid in camera_ids:
            params = rec.cameras[cid].params
            c = cov.get_other_params_cov(params)
            var = float(np.asarray(c)[0, 0]) if c is not None else 0.0
            if var > 0:
                unit.append(100.0 * math.sqrt(var * observations_share) / float(params[0]))
    seconds = time.perf_counter() - t0
    if not unit or not math.isfinite(sigma):
        return {"std_pct": None, "why": "COLMAP could not estimate the covariance",
                "seconds": seconds}
    per_px = float(np.median(unit))
    return {"std_pct": significant(per_px * sigma),
            "per_px_noise_pct": significant(per_px),
            "sensors_range_pct": [significant(min(unit) * sigma),
                                  significant(max(unit) * sigma)],
            "sigma_px": sigma, "sensors": len(unit), "seconds": seconds}
