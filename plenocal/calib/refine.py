"""Joint refinement of every view of every shot under the rig (beyond the paper; rule
``refine``, config ``refine:``).

The paper's complete calibration (Eq. 6, ``M_ij = M_i^A M_j^B``) takes every shot's pose
and the focal length from registration A, which sees only the 28 central views, and
every view's place in its set from registration B; the other views only ride along.
This step adjusts them together, as COLMAP 4 models a camera rig
(:func:`~plenocal.calib.track_sets.rig_reconstruction`):

* each shot is one **frame** (one rig pose, ``rig_from_world``, initialised by Eq. 6);
* its N x N views are the rig's **sensors**, placed by registration B
  (``sensor_from_rig`` = the inverse of ``rig.json``'s ``cam_to_central``; the central
  view is the reference sensor);
* each sensor has one camera, shared by all shots (its principal point as registration
  B's view model gives it);
* the 3-D points (``refine.tracks``, :data:`TRACK_SOURCES`), at most ``max_points`` of
  them: ``central`` the central views' own matches (rule ``match_central``) triangulated
  with the Eq. 6 cameras held fixed and carried into each shot's other views by their
  patches (:mod:`plenocal.calib.central_tracks`); ``views`` the verified matches of every
  view (rule ``view_matches``, the matches Table I triangulates) triangulated the same way
  (:func:`plenocal.verify.reprojection.triangulate`); ``both`` (the default) the two sets
  in one adjustment, each its own points (:func:`plenocal.calib.central_tracks.joined`):
  the central tracks span the shots through their central views, the views' tracks tie
  the views of a set to each other through their own matches (BENCHMARKS.md, "Both track
  sets on fresh captures");
* their observations aligned by their patches to their track's reference observation
  (``refine.align``, :mod:`plenocal.calib.track_alignment`, given the views' images:
  :func:`~plenocal.calib.track_sets.aligned_keypoints`), since SIFT's placement on soft
  views leans the focal length.

COLMAP's bundle adjustment then moves the frames and the points, one frame held (the
gauge). Where the matches leave the shots in groups that share no point (rule view_matches
matches each shot with its nearest shots only, which split two captures of ten in two), one
held frame fixes its own group only: each other group is put back where Eq. 6 places it
relative to the held one (:func:`shot_groups`, :func:`place_groups`; refine.json's
``shot_groups`` and a warning say so). What it may change of
registration B's rig is ``refine.rig`` (:data:`RIG_MODES`):

``hold``
    nothing: the sensors keep B's poses (bit for bit under ``focal: hold``; with the focal
    length refined, B's rig as its model gives it at the refined focal length, whose
    baselines follow the focal length), and their metric baselines fix the scale of the
    result, independently of Eq. 5;
``scale``
    the rig's size (B's baseline): its shape held, the result (frames, points and rig
    together, a gauge of this problem) scaled so that the shots' centres spread as Eq. 6's
    do, i.e. the merge's scale is kept (Eq. 5's r, or the stage's step's:
    :mod:`plenocal.calib.scale`); where the merge took it from the stage's step,
    ``refine.scale: auto`` (the default) fits that step to the refined array shots
    instead of registration A's (:func:`refined_step_scale`: A's shots are off by its pose
    errors, which the refinement takes out);
``scale_pp``
    as ``scale``, and each view's principal point (the central view's held: a common shift
    is a turn of every frame). The exact model's per-view shift is B's alpha; this lets the
    views' own sub-pixel offsets, which the converter leaves, be absorbed where the
    features put them rather than in the poses;
``free``
    each sensor's pose (COLMAP's ``refine_sensor_from_rig``): poorly fixed along the views'
    axes, where a tenth of a millimetre barely changes an image.

``scale_vs_eq5`` reports the scale the adjustment reached over the merge's (the refined
array's size over Eq. 6's): with the rig's poses held, the scale its metric baselines give,
an estimate independent of Eq. 5 and of the stage's step.

The focal length is one for the whole array, as the paper shares it (Section II-B).
``focal: refine`` (the default) frees it in a first pass: each sensor's focal length and
principal point (COLMAP gives each sensor its own camera), their mean focal length weighted
by observations then held, B's rig built again for it, and a second pass as ``refine.rig``
says, of at most ``final_iterations``, started where the first ended (:func:`warm_start`:
the first pass's common principal-point shift turned into the frames); ``focal: hold``
keeps registration A's. A parallel array does not fix the focal length
(it trades off against depth): the hand-held shots' turns do, and registration A sees them
in 28 central views only (:mod:`plenocal.calib.reg_a.uncertainty`: a standard deviation
of 0.3-0.5 % on the simulator's captures). Every view of them fixes it better, on two
conditions measured on ten simulated captures (BENCHMARKS.md, "The focal length from every
view"): the principal points free in that pass (held, the converter's sub-pixel offsets
per view lean on the focal length: +0.7 % from the true cameras), and a robust loss
(``loss: cauchy``, its scale ``loss_scale_px: auto``, :data:`AUTO_LOSS_SCALE` times the
median reprojection error before the adjustment): with the squared loss the observations
with errors of a few tenths of a pixel pulled it 0.5-1.6 % off.

Conventions: internal (OpenCV axes, camera-to-world, pixel centres at integers) in and
out; COLMAP's (cam_from_world, pixel centres at +0.5) only inside, through
:mod:`plenocal.calib.reg_a.colmap`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from plenocal.artifacts.rig import RigB
from plenocal.calib.central_tracks import TrackSet, joined
from plenocal.calib.rig_model import (
    RigModel,
    cameras_of,
    colmap_params,
    frame_centres,
    frame_poses,
    identity_view,
    observation_errors,
    principal_points,
    rescale,
    rig_reconstruction_of,
    rig_views_from_model,
    sensor_params,
    set_intrinsics,
    set_rig,
    shared_focal,
    spread,
    turn_frames,
    turn_of_shift,
    with_focal,
)
from plenocal.calib.scale import array_step_scale
from plenocal.calib.shot_ties import place_groups, point_shots, shot_groups, shot_ties
from plenocal.calib.track_alignment import AlignSettings
from plenocal.calib.track_sets import (
    TrackSource,
    track_sources,
    tracks_of_central_views,
    tracks_of_every_view,
)
from plenocal.calib.view_greys import ViewGreys
from plenocal.camera import PinholeCamera, rotation_angle_deg
from plenocal.config import settings_from, stage_defaults
from plenocal.names import split_key

if TYPE_CHECKING:
    from pycolmap import LossFunctionType, Reconstruction

log = logging.getLogger(__name__)

#: what of registration B's rig the adjustment may change (config refine.rig):
#: hold - nothing (its metric baselines give the scale); scale - its size (its shape held,
#: the result keeps Eq. 5's scale: B's baseline refined, alpha held); scale_pp - its size and
#: each view's principal point (B and, per view, alpha refined); free - each sensor's pose
RIG_MODES = ("hold", "scale", "scale_pp", "free")
#: the result's scale where the rig mode keeps the merge's (config refine.scale): auto - the
#: stage's step fitted to the refined array shots where the merge took its scale from the
#: step, else as merge; merge - the shots' centres spread as Eq. 6's
SCALE_MODES = ("auto", "merge")
FOCAL_MODES = ("hold", "refine")
#: the matches the adjustment uses (config refine.matches): all of view_matches', or those
#: between different shots only (the same view of two shots: no pair within a set)
MATCH_SETS = ("all", "across")
#: where the adjustment's points come from (config refine.tracks): views - the verified
#: matches of every view (rule view_matches); central - the central views' matches (rule
#: match_central, registration A's form), carried into the other views by their patches
#: (:mod:`plenocal.calib.central_tracks`); both - the two sets of points in one adjustment
#: (:func:`plenocal.calib.central_tracks.joined`)
TRACK_SOURCES = ("views", "central", "both")
#: the shots' poses (config refine.frames): refined, or held as Eq. 6 gives them (then only
#: what refine.rig frees of the rig, and the points, move)
FRAME_MODES = ("refine", "hold")
LOSSES = ("trivial", "huber", "cauchy", "soft_l1")
#: loss_scale_px: auto - the robust loss's scale as this share of the observations' median
#: reprojection error before the adjustment (BENCHMARKS.md, "The focal length from every view")
AUTO_LOSS_SCALE = 0.8
#: the adjustments' first trust region (Ceres' initial_trust_region_radius; its default and
#: COLMAP's is 1e4): so large that the first steps are Gauss-Newton's. The passes start
#: from Eq. 6, near their minimum, where Levenberg-Marquardt's damped first steps crept along
#: the focal length's shallow valley: at 1e4 the focal pass left it 0.41 / 0.29 / 0.22 /
#: 0.20 % off the truth after 4 / 6 / 8 / 10 iterations on one capture, and 15 were needed;
#: at 1e9, 0.20 % after 6 (BENCHMARKS.md, "The refinement's first steps", which measures the
#: default of ``max_iterations`` chosen with it). A step that raises the cost is rejected and
#: the region shrinks, as at any radius.
INITIAL_TRUST_REGION = 1e9
#: Ceres' linear solver in the adjustments. COLMAP picks the Schur complement for problems
#: of this size (SPARSE_SCHUR), whose elimination sums each point's share of the reduced
#: system on several threads in whatever order they finish (ceres-solver issues 577 and
#: 664): on two threads the refined cameras came out other bytes run to run, so the step
#: ran on one. The normal equations solved by sparse Cholesky (CHOLMOD) reach the same
#: minimum (over the twenty kept captures the focal lengths equal to 1e-9 of themselves,
#: the poses to 1e-10) in a little less time (default-s2's two passes 42.8 and 38.4 s
#: against 45.3 and 45.8 s on one thread, alternating; default-s1's 24.3 s on two), and
#: Ceres' threads do not change their bytes (each residual block's Jacobian is evaluated
#: into a place of its own). The OpenMP threads that pycolmap's CHOLMOD starts
#: with (``OMP_NUM_THREADS`` when the process starts; Snakemake sets it to the job's
#: threads) change the last digits (wide-s1's focal length 2110.668611612627 px with one,
#: 2110.6686116311516 px with two), the same run after run (BENCHMARKS.md, "The
#: refinement's adjustments by sparse Cholesky"), so rule refine's script pins them to one
#: before pycolmap loads (:mod:`plenocal.library_threads`): its thread count then changes
#: the time, not the bytes.
LINEAR_SOLVER = "SPARSE_NORMAL_CHOLESKY"
_REFINE = stage_defaults("refine")  # the defaults: config.schema.yaml's refine block
_SFM = stage_defaults("sfm")  # the seed of COLMAP's steps


@dataclass(frozen=True)
class RefineSettings:
    """The ``refine:`` block of the config (config.schema.yaml documents each key)."""

    enabled: bool = _REFINE["enabled"]
    focal: str = _REFINE["focal"]
    rig: str = _REFINE["rig"]
    scale: str = _REFINE["scale"]
    matches: str = _REFINE["matches"]
    tracks: str = _REFINE["tracks"]
    carry_every: int = _REFINE["carry_every"]
    frames: str = _REFINE["frames"]
    max_points: int = _REFINE["max_points"]
    max_error_px: float = _REFINE["max_error_px"]
    min_angle_deg: float = _REFINE["min_angle_deg"]
    loss: str = _REFINE["loss"]
    loss_scale_px: float | str = _REFINE["loss_scale_px"]
    max_iterations: int = _REFINE["max_iterations"]
    final_iterations: int = _REFINE["final_iterations"]
    max_shift_pct: float = _REFINE["max_shift_pct"]
    min_tie_points: int = _REFINE["min_tie_points"]
    min_gain_pct: float = _REFINE["min_gain_pct"]
    focal_sd: bool = _REFINE["focal_sd"]
    align: AlignSettings = AlignSettings()
    seed: int = _SFM["seed"]
    num_threads: int = _REFINE["num_threads"]

    def __post_init__(self) -> None:
        for key, value, allowed in (("focal", self.focal, FOCAL_MODES),
                                    ("rig", self.rig, RIG_MODES),
                                    ("scale", self.scale, SCALE_MODES),
                                    ("matches", self.matches, MATCH_SETS),
                                    ("tracks", self.tracks, TRACK_SOURCES),
                                    ("frames", self.frames, FRAME_MODES),
                                    ("loss", self.loss, LOSSES)):
            if value not in allowed:
                raise ValueError(f"config refine.{key} = {value!r}: use one of "
                                 f"{', '.join(allowed)}")
        if self.loss_scale_px != "auto" and not (isinstance(self.loss_scale_px, int | float)
                                                 and self.loss_scale_px > 0):
            raise ValueError(f"config refine.loss_scale_px = {self.loss_scale_px!r}: a "
                             "positive number of pixels, or auto")
        if self.carry_every < 1:
            raise ValueError(f"config refine.carry_every = {self.carry_every}: at least 1 "
                             "(1 carries each point into every view)")
        if self.max_points < 100:
            raise ValueError(f"config refine.max_points = {self.max_points}: at least 100")

    @property
    def scale_from_eq5(self) -> bool:
        """Whether the result keeps Eq. 5's scale (every rig mode but hold, and whenever the
        shots' poses are held)."""
        return self.rig != "hold" or self.frames == "hold"

    @classmethod
    def from_config(cls, cfg: Mapping, seed: int = _SFM["seed"],
                    num_threads: int | None = None) -> RefineSettings:
        """The ``refine:`` block ``cfg``; ``seed`` is sfm.seed; ``num_threads`` (a job's
        threads) overrides the block's ``num_threads``."""
        keys = {f for f in cls.__dataclass_fields__ if f != "seed"}
        kw = {k: cfg[k] for k in keys if k in cfg}
        if isinstance(kw.get("align"), Mapping):
            kw["align"] = settings_from(AlignSettings, kw["align"])
        if num_threads is not None:
            kw["num_threads"] = num_threads
        return cls(**kw, seed=seed)


def _loss(name: str) -> LossFunctionType:
    import pycolmap  # noqa: PLC0415

    return getattr(pycolmap.LossFunctionType, name.upper())


def _adjustment_setup(rec: Reconstruction, model: RigModel, settings: RefineSettings, *,
                      refine_focal: bool, refine_rig: bool, hold_frame: str, loss_scale_px: float,
                      refine_pp: bool = False) -> tuple:
    """The options and the configuration (``pycolmap.BundleAdjustmentOptions``,
    ``pycolmap.BundleAdjustmentConfig``) of :func:`bundle_adjust`'s problem, but for the
    solver's own settings: what is held and what moves, and the loss."""
    import pycolmap  # noqa: PLC0415

    cfg = pycolmap.BundleAdjustmentConfig()
    for image_id in sorted(rec.images):
        cfg.add_image(image_id)
    for shot in held_shots(model, settings, hold_frame):
        cfg.set_constant_rig_from_world_pose(model.frame_of_shot[shot])
    if refine_pp and not refine_focal:
        cfg.set_constant_cam_intrinsics(model.camera_of_view[model.central])
    o = pycolmap.BundleAdjustmentOptions()
    o.refine_focal_length = refine_focal
    o.refine_principal_point = refine_pp
    o.refine_extra_params = False
    o.refine_sensor_from_rig = refine_rig
    o.refine_rig_from_world = True
    o.ceres.loss_function_type = _loss(settings.loss)
    o.ceres.loss_function_scale = float(loss_scale_px)
    return o, cfg


def held_shots(model: RigModel, settings: RefineSettings, hold_frame: str) -> list[str]:
    """The shots whose poses the adjustments hold: every one where ``refine.frames`` is
    hold, else ``hold_frame`` (the gauge)."""
    return sorted(model.frame_of_shot) if settings.frames == "hold" else [hold_frame]


def focal_pass_std(rec: Reconstruction, model: RigModel, settings: RefineSettings, *,
                   refine_rig: bool, hold_frame: str, loss_scale_px: float,
                   work_dir: str | Path | None = None) -> dict:
    """The focal length's standard deviation at the end of the focal pass (config
    ``refine.focal_sd``; :mod:`plenocal.calib.refine_uncertainty`), its problem set up as
    the pass's (:func:`_adjustment_setup`) on a thinned copy of ``rec`` where ``rec`` holds
    more than :data:`~plenocal.calib.refine_uncertainty.MAX_OBSERVATIONS` observations.
    Reads ``rec``, changes nothing."""
    import pycolmap  # noqa: PLC0415

    from plenocal.calib import refine_uncertainty as ru  # noqa: PLC0415

    o, cfg = _adjustment_setup(rec, model, settings, refine_focal=True, refine_rig=refine_rig,
                               hold_frame=hold_frame, loss_scale_px=loss_scale_px,
                               refine_pp=True)
    errors = observation_errors(rec, work_dir)
    every = ru.points_every(len(errors))
    problem, kept, total = ru.thinned(rec, every) if every > 1 else (rec, len(errors),
                                                                      len(errors))
    # setting the problem up rewrites the frames' poses in their last bits (their
    # parametrisation): kept and put back, so that the refinement's result is the same
    # bytes with and without this estimate (a thinned copy's are its own)
    poses = {f: np.array(rec.frames[f].rig_from_world.params) for f in rec.frames}
    try:
        adjuster = pycolmap.create_default_ceres_bundle_adjuster(o, cfg, problem)
        held = {model.frame_of_shot[s] for s in held_shots(model, settings, hold_frame)}
        frames = [f for f in sorted(model.frame_of_shot.values()) if f not in held]
        out = ru.sensor_focal_std_pct(problem, sorted(set(model.camera_of_view.values())),
                                      frames, errors_px=errors, bundle_adjuster=adjuster,
                                      observations_share=kept / max(total, 1))
        del adjuster
    finally:
        for f, params in poses.items():
            rec.frames[f].rig_from_world.params[:] = params
        del problem
    # the time in the log, not in refine.json (the same bytes run after run)
    seconds = out.pop("seconds")
    out.update(points_every=every, observations=kept)
    log.info("the focal length's standard deviation (the focal pass's covariance on every "
             "%d-th point, %d of %d observations): %s (%.1f s)", every, kept, total,
             "not estimated" if out["std_pct"] is None else f"{out['std_pct']:.3f} %",
             seconds)
    return out


def bundle_adjust(rec: Reconstruction, model: RigModel, settings: RefineSettings, *,
                  refine_focal: bool, refine_rig: bool, hold_frame: str, loss_scale_px: float,
                  refine_pp: bool = False, max_iterations: int | None = None) -> dict:
    """COLMAP's bundle adjustment of ``rec``: frames and points, each sensor's focal length
    where ``refine_focal``, each sensor's principal point where ``refine_pp`` (the central
    view's held unless the focal lengths are freed too: a common shift is a turn of every
    frame), the rig's sensors where ``refine_rig``; the frame of ``hold_frame`` held (the
    gauge's rotation and translation); ``settings.loss`` at the scale ``loss_scale_px``;
    at most ``max_iterations`` (``settings.max_iterations`` if None). Returns the solver's
    summary."""
    import pycolmap  # noqa: PLC0415

    o, cfg = _adjustment_setup(rec, model, settings, refine_focal=refine_focal,
                               refine_rig=refine_rig, hold_frame=hold_frame,
                               loss_scale_px=loss_scale_px, refine_pp=refine_pp)
    s = o.ceres.solver_options
    s.max_num_iterations = int(settings.max_iterations if max_iterations is None
                               else max_iterations)
    s.initial_trust_region_radius = INITIAL_TRUST_REGION
    # the normal equations by sparse Cholesky, not COLMAP's choice (the Schur complement):
    # the same bytes run after run on any number of Ceres threads, and faster (LINEAR_SOLVER)
    o.ceres.auto_select_solver_type = False
    s.linear_solver_type = getattr(type(s.linear_solver_type), LINEAR_SOLVER)
    s.num_threads = int(settings.num_threads)
    o.ceres.min_num_residuals_for_cpu_multi_threading = 0  # the threads given, always
    t0 = time.perf_counter()
    summary = pycolmap.create_default_bundle_adjuster(o, cfg, rec).solve().todict()
    ceres = summary["ceres_summary"]
    out = {"termination": str(summary["termination_type"]).rsplit(".", 1)[-1],
           "iterations": int(ceres["num_successful_steps"] + ceres["num_unsuccessful_steps"]),
           "initial_cost": float(ceres["initial_cost"]), "final_cost": float(ceres["final_cost"]),
           "residuals": int(summary["num_residuals"]),
           "linear_solver": str(ceres["linear_solver_type_used"]).rsplit(".", 1)[-1],
           "threads": int(ceres["num_threads_used"])}
    seconds = time.perf_counter() - t0
    # Ceres calls a pass that used every iteration it was given NO_CONVERGENCE: here the
    # cap is the design (the passes' iterations are chosen by measurement, INITIAL_TRUST_REGION)
    capped = (out["termination"] == "NO_CONVERGENCE"
              and out["iterations"] >= s.max_num_iterations)
    ending = (f"its cap of {s.max_num_iterations} iterations reached, as set (Ceres reports "
              "NO_CONVERGENCE)" if capped
              else f"{out['termination']} after {out['iterations']} iterations")
    log.info("bundle adjustment (focal %s, principal points %s, rig %s): %s, cost %.6g -> "
             "%.6g, %.1f s", "refined" if refine_focal else "held",
             "refined" if refine_pp else "held", "refined" if refine_rig else "held", ending,
             out["initial_cost"], out["final_cost"], seconds)
    return out


# --- the refinement ------------------------------------------------------------------


@dataclass
class Refinement:
    """The refined cameras and what the report and gt_errors read of the run."""

    cameras: dict[str, PinholeCamera]
    report: dict
    rig_views: dict[str, tuple[np.ndarray, np.ndarray]]
    sensors_before: dict[int, np.ndarray]
    sensors_after: dict[int, np.ndarray]


def _stats(e: np.ndarray) -> dict:
    if e.size == 0:
        return {"n": 0, "mean_px": None, "median_px": None}
    return {"n": int(e.size), "mean_px": float(e.mean()), "median_px": float(np.median(e))}


def refine_calibration(eq6: Mapping[str, PinholeCamera], rig: RigB, database: str | Path | None,
                       settings: RefineSettings, *, hold_shot: str,
                       rig_at_focal: Callable[[float], RigB] | None = None,
                       work_dir: str | Path | None = None,
                       images: Mapping[str, str | Path] | None = None,
                       align_threads: int | None = None,
                       step_m: float | None = None,
                       view_database: str | Path | None = None,
                       track_sets: Mapping[str, TrackSource] | None = None
                       ) -> Refinement:
    """Refine the Eq. 6 calibration ``eq6`` (every view of every shot, metres) under the rig
    ``rig`` on the verified matches of ``database``: the central views' (rule
    ``match_central``) with ``settings.tracks`` central or both, every view's (rule
    ``view_matches``) with views; with both, also those of ``view_database`` (rule
    ``view_matches``') (module docstring).
    ``hold_shot``: the shot whose pose is held (the gauge). ``rig_at_focal``: registration
    B's rig rebuilt for another focal length (its baselines follow the focal length:
    :func:`plenocal.calib.reg_b.exact_model.exact_model`); without it the rig keeps B's
    geometry when the focal length changes. ``images``: view key -> its image file, for
    ``settings.align`` (without them the observations stay where SIFT placed them), aligned
    on ``align_threads`` threads (``settings.num_threads`` if None; the same result on any
    number). ``step_m``: the stage's step (metres) where the merge took its scale from it
    (``scale.json``'s ``chosen``: ``array_step``), None otherwise; with ``refine.scale:
    auto`` the result's scale is that step fitted to the refined array shots
    (:func:`refined_step_scale`). ``track_sets``: source (:func:`track_sources`) -> the
    track set and its alignment's statistics, made beforehand (rule ``refine_tracks``:
    :func:`~plenocal.calib.track_sets.make_track_set`), or a function that reads them
    (rule ``refine``: then no reference outlives the rig reconstruction); the databases
    and images are not read."""
    t0 = time.perf_counter()
    views = rig.view_poses()
    shots = sorted({split_key(k)[0] for k in eq6})
    missing = [f"{s}/{v}" for s in shots for v in views if f"{s}/{v}" not in eq6]
    if missing:
        raise ValueError(f"the Eq. 6 calibration lacks {len(missing)} views of the rig "
                         f"({', '.join(missing[:5])}...): rerun rule merge")
    if hold_shot not in shots:
        raise ValueError(f"refinement: the held shot {hold_shot} is not calibrated")
    central = identity_view(views)
    shot_poses = {s: eq6[f"{s}/{central}"].cam_to_world for s in shots}
    # the track sets' plain data go out of scope here, before the adjustments: on a 9 x 3
    # array with both track sets (dense-s34) the job's peak 2.32 -> 1.90 GB, the same
    # cameras
    rec, model, n_tri, n_used, align, t_tri = _tracks_rig(
        eq6, views, central, shot_poses, rig, database, view_database, settings, images,
        align_threads, work_dir, track_sets)
    log.info("rig reconstruction: %d shots x %d views, %d of %d points (%s)", len(shots),
             len(views), n_used, n_tri, "track sets made beforehand" if track_sets is not None
             else f"{t_tri:.1f} s triangulation")
    return _adjusted(rec, model, eq6, rig, views, shots, central, shot_poses, settings,
                     hold_shot=hold_shot, rig_at_focal=rig_at_focal, step_m=step_m,
                     points={"triangulated": n_tri, "used": n_used}, align=align, t0=t0,
                     t_tri=t_tri, work_dir=work_dir)


def _tracks_rig(eq6: Mapping[str, PinholeCamera], views: Mapping[str, tuple], central: str,
                shot_poses: Mapping[str, np.ndarray], rig: RigB, database: str | Path,
                view_database: str | Path | None, settings: RefineSettings,
                images: Mapping[str, str | Path] | None, align_threads: int | None,
                work_dir: str | Path | None,
                track_sets: Mapping[str, TrackSource] | None = None) -> tuple:
    """The rig reconstruction on the tracks ``settings.tracks`` names (module docstring):
    (reconstruction, :class:`RigModel`, points triangulated, points used, the alignment's
    statistics, the triangulation's seconds). ``track_sets``: the sets made beforehand
    (:func:`refine_calibration`), joined as they would be here."""
    if track_sets is not None:
        sources = track_sources(settings)
        missing = [s for s in sources if s not in track_sets]
        if missing:
            raise ValueError(f"refine.tracks {settings.tracks} needs the track sets of "
                             f"{', '.join(sources)}: {', '.join(missing)} not given (rule "
                             "refine_tracks makes them)")
        sets = [t() if callable(t) else t for t in (track_sets[s] for s in sources)]
        ts, align = sets[0]
        if len(sets) == 2:
            ts = joined(ts, sets[1][0])
            align = {"enabled": True, "central": align, "views": sets[1][1]}
        del sets
        return _rig_of_tracks(ts, views, shot_poses, rig, settings) + (align, 0.0)
    if settings.tracks == "both" and view_database is None:
        raise ValueError("refine.tracks both adds the matches of every view to the central "
                         "views': the view database (rule view_matches) is needed")
    if settings.tracks == "both" and images is not None:
        # both alignments read the same views: decoded once (freed with this call, before
        # the adjustments)
        images = ViewGreys(images)
    if settings.tracks == "views":
        ts, align, t_tri = tracks_of_every_view(eq6, database, settings, images, align_threads,
                                        work_dir)
    else:
        ts, align, t_tri = tracks_of_central_views(eq6, central, database, settings, images,
                                           align_threads, work_dir)
    if settings.tracks == "both":
        ts_views, align_views, t_views = tracks_of_every_view(eq6, view_database, settings, images,
                                                      align_threads, work_dir)
        ts, t_tri = joined(ts, ts_views), t_tri + t_views
        align = {"enabled": True, "central": align, "views": align_views}
    return _rig_of_tracks(ts, views, shot_poses, rig, settings) + (align, t_tri)


def _rig_of_tracks(ts: TrackSet, views: Mapping[str, tuple], shot_poses: Mapping[str, np.ndarray],
                   rig: RigB, settings: RefineSettings) -> tuple:
    """(the rig reconstruction of ``ts``, its :class:`RigModel`, the points triangulated,
    the points used)."""
    if len(ts.points) < 100:
        raise ValueError(f"refinement: only {len(ts.points)} points seen in three or more "
                         f"views ({_TOO_FEW[settings.tracks]}), or set refine.enabled: false")
    rec, model = rig_reconstruction_of(ts.names, ts.points, ts.keypoints, views, shot_poses,
                                       rig.width, rig.height)
    return rec, model, ts.triangulated, len(ts.points)


#: the remedy where a track source gives too few points
_TOO_FEW = {
    "views": "the views have too few matches: see matches/matches.json",
    "central": "of the central views' matches; set refine.tracks: views or both (with the "
               "matches of every view)",
    "both": "the central views' and every view's matches together; see "
            "matches/matches.json",
}


def warm_start(rec: Reconstruction, model: RigModel,
               views: Mapping[str, tuple[np.ndarray, np.ndarray]], settings: RefineSettings,
               focal: float, hold_shot: str) -> float:
    """Registration B's cameras at the shared focal length (``views``: the rig built again
    for ``focal``) set back after the focal pass, so that the final pass starts where the
    focal pass ended; the turn it took (degrees).

    The focal pass frees every view's principal point, the central view's too, and with
    one frame held a shift common to all of them is a turn of every other frame (module
    docstring): the pass ends with them shifted together by about a pixel (small-s41: 1.09,
    0.23 px), the frames turned to match. B's principal points set back alone leave the
    final pass that turn to make again, every frame and point about the held one, from a
    cost 2-4.7 times the focal pass's end (BENCHMARKS.md, "The final pass started where the
    focal pass ended"). So the central view's shift from B's is turned into the frames
    (:func:`turn_of_shift`, :func:`turn_frames`: the same images to first order), and where
    the final pass refines the principal points (``rig: scale_pp``) each view starts at
    the focal pass's, less that shift: the central view's is B's, as before. With
    ``frames: hold`` no frame may turn: B's cameras only, as before."""
    focal_pass = principal_points(rec, model)
    b = {v: np.array(colmap_params(views[v][0])[2:4]) for v in model.camera_of_view}
    if settings.frames == "hold":
        set_intrinsics(rec, model, views)
        return 0.0
    shift = focal_pass[model.central] - b[model.central]
    offsets = None
    if settings.rig == "scale_pp":
        offsets = {v: (np.zeros(2) if v == model.central else focal_pass[v] - shift - b[v])
                   for v in model.camera_of_view}
    set_intrinsics(rec, model, views, offsets)
    turn = turn_of_shift(shift, focal)
    turn_frames(rec, model, turn, hold_shot)
    angle = rotation_angle_deg(turn, np.eye(3))
    log.info("the focal pass's common principal-point shift (%+.3f, %+.3f) px turned into "
             "the frames (%.4f deg) before the final pass", shift[0], shift[1], angle)
    return angle


def _adjusted(rec: Reconstruction, model: RigModel, eq6: Mapping[str, PinholeCamera],
              rig: RigB, views: Mapping[str, tuple[np.ndarray, np.ndarray]], shots: list[str],
              central: str, shot_poses: Mapping[str, np.ndarray], settings: RefineSettings, *,
              hold_shot: str, rig_at_focal: Callable[[float], RigB] | None,
              step_m: float | None, points: dict, align: dict, t0: float, t_tri: float,
              work_dir: str | Path | None) -> Refinement:
    """The adjustments of :func:`refine_calibration` on the rig reconstruction ``rec``, and
    its report."""
    before = observation_errors(rec, work_dir)
    size_eq6 = spread(frame_centres(rec, model))
    sensors_before = sensor_params(rec)
    focal_a = float(rig.focal_px)
    loss_scale = loss_scale_of(settings, before)
    passes = {}
    free_rig = settings.rig == "free"
    focal, per_sensor, rig_views = focal_a, {}, views
    focal_sd = None
    if settings.focal == "refine":
        # each sensor's focal length and principal point freed; the shared focal length
        # their weighted mean, the principal points B's again (module docstring)
        passes["focal"] = bundle_adjust(rec, model, settings, refine_focal=True,
                                        refine_rig=free_rig, hold_frame=hold_shot,
                                        refine_pp=True, loss_scale_px=loss_scale)
        focal, per_sensor = shared_focal(rec, model)
        if settings.focal_sd:
            focal_sd = focal_pass_std(rec, model, settings, refine_rig=free_rig,
                                      hold_frame=hold_shot, loss_scale_px=loss_scale,
                                      work_dir=work_dir)
        rig_views = (rig_at_focal(focal).view_poses() if rig_at_focal is not None
                     else {v: (with_focal(K, focal), M) for v, (K, M) in views.items()})
        passes["focal"]["turn_deg"] = warm_start(rec, model, rig_views, settings, focal,
                                                 hold_shot)
        if not free_rig:
            set_rig(rec, model, rig_views)
            sensors_before = sensor_params(rec)
    passes["final"] = bundle_adjust(rec, model, settings, refine_focal=False,
                                    refine_rig=free_rig, hold_frame=hold_shot,
                                    refine_pp=settings.rig == "scale_pp",
                                    loss_scale_px=loss_scale,
                                    max_iterations=(settings.final_iterations
                                                    if settings.focal == "refine" else None))
    ties = point_shots(rec, model)
    groups = shot_groups(ties, model.frame_of_shot)
    placed = {}
    if len(groups) > 1 and settings.frames == "refine":
        # no point ties one group to another: each keeps Eq. 6's place (place_groups)
        placed = place_groups(rec, model, shot_poses, groups, hold_shot)
    # the scale the adjustment reached: with the rig's sensors held, the one their metric
    # baselines give (independent of Eq. 5); a free rig leaves it where Eq. 6 put it
    scale_rig = spread(frame_centres(rec, model)) / size_eq6
    applied, step_fit = 1.0, None
    if settings.scale_from_eq5:
        if settings.scale == "auto" and step_m is not None:
            step_fit = refined_step_scale(rec, model, step_m)
        applied = 1.0 / scale_rig if step_fit is None else step_fit["r"]
        rescale(rec, applied)
    after = observation_errors(rec, work_dir)
    cams = cameras_of(rec)
    refined_rig = rig_views_from_model(rec, model)
    rig_change = {v: {"centre_mm": 1000.0 * float(np.linalg.norm(refined_rig[v][:3, 3]
                                                                 - rig_views[v][1][:3, 3])),
                      "rotation_deg": rotation_angle_deg(refined_rig[v][:3, :3],
                                                         rig_views[v][1][:3, :3])}
                  for v in sorted(refined_rig)}
    report = {
        "settings": asdict(settings),
        "shots": len(shots),
        "views": len(cams),
        "points": points,
        "observations": {"before": _stats(before), "after": _stats(after)},
        "loss": {"type": settings.loss, "scale_px": loss_scale},
        "alignment": align,
        "focal_px": {"registration_a": focal_a, "refined": focal,
                     "change_pct": 100.0 * (focal / focal_a - 1.0),
                     "per_sensor": per_sensor,
                     **({} if focal_sd is None else {"std": focal_sd})},
        "scale_vs_eq5": {
            "rig": scale_rig,
            "result": spread(frame_centres(rec, model)) / size_eq6,
            "what": "the shots' centres' spread over Eq. 6's, i.e. the scale over Eq. 5's r: "
                    "'rig' as the adjustment reached it (with the rig's sensor poses held, "
                    "the scale their metric baselines give), 'result' what was written"},
        "scale_source": scale_source(settings, step_fit),
        "scale_applied": applied,
        "array_step_fit": step_fit,
        "hold_shot": hold_shot,
        "rig_change": rig_change,
        "passes": passes,
    }
    report.update(shot_shifts(eq6, cams, shots, central, settings.max_shift_pct, ties,
                              settings.min_tie_points))
    report["shot_groups"] = groups
    if len(groups) > 1:
        report["group_placement_mm"] = placed
        msg = (f"the matches split the {len(shots)} shots into {len(groups)} groups that "
               f"share no point ({'; '.join(', '.join(g) for g in groups)}): each group was "
               "adjusted within itself and keeps Eq. 6's place relative to the others "
               "(rule view_matches matches each shot with its sfm.view_matching."
               "shot_neighbours nearest shots only; more, or null, links them)")
        report["warnings"].append(msg)
        log.warning(msg)
    report["gain"] = fit_gain(before, after, settings.min_gain_pct)
    corrected = len(report["corrected_shots"])
    if report["rejected"]:
        log.warning(report["warnings"][0])
        cams = dict(eq6)
    elif not report["gain"]["kept"]:
        log.info(report["gain"]["why"])
        report["rejected"] = True
        # the shots' corrections go with the refinement (their warnings say it is kept)
        report["corrected_shots"] = {}
        del report["warnings"][:corrected]
        cams = dict(eq6)
    else:
        for msg in report["warnings"][:corrected]:
            log.warning(msg)
    log.info("refinement took %.1f s (%.1f s triangulation)", time.perf_counter() - t0, t_tri)
    log.info("refined: focal %.4f -> %.4f px (%+.4f %%), scale vs Eq. 5 %.6f (rig held: "
             "%.6f), observations mean %.4f -> %.4f px", focal_a, focal,
             report["focal_px"]["change_pct"], report["scale_vs_eq5"]["result"], scale_rig,
             report["observations"]["before"]["mean_px"] or math.nan,
             report["observations"]["after"]["mean_px"] or math.nan)
    return Refinement(cams, report, rig_views, sensors_before, sensor_params(rec))


def refined_step_scale(rec: Reconstruction, model: RigModel, step_m: float) -> dict | None:
    """The stage's step ``step_m`` fitted to the refined array shots
    (:func:`plenocal.calib.scale.array_step_scale` on the frames' poses, the units the
    adjustment left): its ``r`` is the factor that gives them that step, metres per unit.
    Registration A's array shots, which the merge's scale is fitted to, are off by its
    pose errors (0.03-0.10 mm on the simulator's captures, their scale up to 0.3 % off);
    the refined ones by far less. None where fewer than two array shots are refined."""
    return array_step_scale(frame_poses(rec, model), step_m)


def scale_source(settings: RefineSettings, step_fit: dict | None) -> str:
    """What set the written result's scale (refine.json's ``scale_source``)."""
    if not settings.scale_from_eq5:
        return "registration B's rig (its metric baselines)"
    if step_fit is not None:
        return (f"the stage's step ({1000.0 * step_fit['step_m']:g} mm) fitted to the "
                f"{step_fit['n_shots']} refined array shots (refine.scale: auto)")
    # refine.scale: merge - Eq. 6's r, which rule scale took from Eq. 5 or from the stage's
    # step (scale.reference; merge/scale.json says which)
    return ("the merge's r (the result scaled to Eq. 6's spread, the rig with it: Eq. 5's "
            "r or the stage's step, as merge/scale.json's chosen says)")


def loss_scale_of(settings: RefineSettings, before: np.ndarray) -> float:
    """The robust loss's scale (px): ``settings.loss_scale_px``, or with ``auto``
    :data:`AUTO_LOSS_SCALE` times the median of ``before`` (the observations' reprojection
    errors under the Eq. 6 cameras), so that it follows the views' own feature noise."""
    if settings.loss_scale_px != "auto":
        return float(settings.loss_scale_px)
    if not before.size or not float(np.median(before)) > 0:
        raise ValueError("refinement: no observation error to take refine.loss_scale_px: "
                         "auto from; set it in pixels")
    return AUTO_LOSS_SCALE * float(np.median(before))


def fit_gain(before: np.ndarray, after: np.ndarray, min_gain_pct: float) -> dict:
    """Whether the refinement explains the views clearly better than Eq. 6: the median
    reprojection error of its observations must fall by at least ``min_gain_pct`` %.

    Measured over ten simulated captures (BENCHMARKS.md, "Accuracy over captures"): with
    the focal length from every view and the Cauchy loss (the defaults) the median fell
    by 8.8-17.6 % on all ten and every one came nearer the truth. Before, with A's focal
    length held and the squared loss, it moved by -0.3 to +0.9 % on the default captures
    (whose Eq. 6 result already fitted the views), and kept by force the adjustment there
    followed the converter's bias in the outer views and moved the centres 26-63 %
    farther from the truth. The default 1 % stays for such captures; one whose gain falls
    near it is a judgement call either way, and refine.json says which way it went."""
    b, a = float(np.median(before)), float(np.median(after))
    gain = 100.0 * (1.0 - a / b) if b > 0 else 0.0
    kept = gain >= min_gain_pct
    why = (f"the refinement lowered the median reprojection error by {gain:.2f} % "
           f"({b:.4f} -> {a:.4f} px), {'at least' if kept else 'less than'} "
           f"refine.min_gain_pct = {min_gain_pct:g} %: "
           + ("kept" if kept else "the Eq. 6 result already fits the views as well; "
              "calibration/ holds it"))
    return {"median_before_px": b, "median_after_px": a, "gain_pct": gain,
            "min_gain_pct": float(min_gain_pct), "kept": bool(kept), "why": why}


def shot_shifts(eq6: Mapping[str, PinholeCamera], refined: Mapping[str, PinholeCamera],
                shots: list[str], central: str, max_shift_pct: float,
                ties: list[frozenset[str]] | None = None,
                min_tie_points: int = _REFINE["min_tie_points"]) -> dict:
    """How far the refinement moved each shot from Eq. 6 (its central view's centre, mm,
    and orientation, deg), after the rigid motion that best maps the Eq. 6 shots onto the
    refined ones (the gauge), and whether that is to be trusted. A change of scale is not
    taken out: where the result's scale rightly differs from Eq. 6's (B's baselines under
    ``rig: hold``, the stage's step under ``scale: auto``), it reads as shifts that grow
    with a shot's distance from the middle (1 % as up to 0.9 mm on default-s111, past the
    default gate; under the defaults the two scales agree to 3e-5).

    A shot that moved more than ``max_shift_pct`` % of the array's size (the RMS distance
    of the shots from their mean) is a correction of Eq. 6 where at least
    ``min_tie_points`` of the adjustment's points ``ties`` (:func:`point_shots`) tie it to
    the shots that moved less: registration A, which places every shot of Eq. 6, can place
    one badly (a hand-held shot 8.5 mm and 0.33 deg off on a capture of the tele geometry,
    whose refinement, the shot tied to the others by 471 points, met every target), and
    the refinement is kept, with a warning that names the shot. Where fewer points tie it
    (or ``ties`` is None), the shot slid where no point held it: the refinement is
    rejected, with a warning, and the Eq. 6 result is written instead (a group of shots
    that no point tied to the held one slid 5-7 mm along the views' axes on two captures
    of ten, until :func:`place_groups` kept such groups at Eq. 6's place)."""
    from plenocal.verify.gt_errors import pose_similarity  # noqa: PLC0415

    src = np.array([eq6[f"{s}/{central}"].centre for s in shots])
    dst = np.array([refined[f"{s}/{central}"].centre for s in shots])
    rot_src = [eq6[f"{s}/{central}"].R for s in shots]
    rot_dst = [refined[f"{s}/{central}"].R for s in shots]
    size = spread({s: c for s, c in zip(shots, src, strict=True)})
    limit = max_shift_pct / 100.0 * size

    def shifts(use: np.ndarray) -> tuple[np.ndarray, list[float]]:
        _, R, t = pose_similarity(src[use], dst[use], [rot_src[i] for i in np.flatnonzero(use)],
                                  [rot_dst[i] for i in np.flatnonzero(use)], with_scale=False)
        return (np.linalg.norm(src @ R.T + t - dst, axis=1),
                [rotation_angle_deg(R @ a, b) for a, b in zip(rot_src, rot_dst, strict=True)])

    moved, turned = shifts(np.ones(len(shots), bool))
    # the gauge again without the shots past the limit (at least three left): one shot
    # moved far pulls the least-squares motion, and the others with it, past the limit
    if (moved > limit).any() and (moved <= limit).sum() >= 3:
        moved, turned = shifts(moved <= limit)
    far = [s for s, m in zip(shots, moved, strict=True) if m > limit]
    stayed = set(shots) - set(far)
    held = (shot_ties(ties, far, stayed) if ties is not None else dict.fromkeys(far, 0))
    loose = [s for s in far if held[s] < min_tie_points]
    worst = int(np.argmax(moved))
    shift = dict(zip(shots, moved, strict=True))
    turn = dict(zip(shots, turned, strict=True))
    out = {"shot_shift_mm": {s: 1000.0 * float(m) for s, m in shift.items()},
           "shot_turn_deg": turn,
           "max_shift_mm": 1000.0 * float(moved[worst]), "limit_mm": 1000.0 * limit,
           "shot_ties": None if ties is None else shot_ties(ties, list(shots)),
           "corrected_shots": {} if loose else {s: held[s] for s in far},
           "min_tie_points": int(min_tie_points),
           "rejected": bool(loose), "warnings": []}
    if loose:
        s = max(loose, key=lambda k: shift[k])
        out["warnings"].append(
            f"the joint refinement moved shot {s} by {1000 * shift[s]:.2f} mm from Eq. 6 "
            f"(more than refine.max_shift_pct = {max_shift_pct:g} % of the array's "
            f"{1000 * size:.1f} mm), and only {held[s]} of its points tie it to the shots "
            f"that moved less (refine.min_tie_points = {min_tie_points}): it was rejected "
            "and calibration/ holds the Eq. 6 result; the shots' matches do not tie the "
            "array together (see matches/matches.json), or raise refine.max_shift_pct")
    else:
        for s in far:
            out["warnings"].append(
                f"Eq. 6 placed shot {s} {1000 * shift[s]:.2f} mm and {turn[s]:.3f} "
                f"deg from where the joint refinement puts it, {held[s]} points tying it to "
                f"the shots that moved less than {1000 * limit:.2f} mm: registration A "
                "placed it badly (see reg_a/), and the refinement is kept (calibration/eq6/ "
                "holds Eq. 6's)")
    return out


