"""Joint refinement of every view of every shot under the rig (beyond the paper; rule
``refine``, config ``refine:``).

The paper's complete calibration (Eq. 6, ``M_ij = M_i^A M_j^B``) takes every shot's pose
and the focal length from registration A, which sees only the 28 central views, and
every view's place in its set from registration B; the other views only ride along.
This step adjusts them together, as COLMAP 4 models a camera rig
(:func:`rig_reconstruction`):

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
  :func:`aligned_keypoints`), since SIFT's placement on soft views leans the focal length.

COLMAP's bundle adjustment then moves the frames and the points, one frame held (the
gauge). Where the matches leave the shots in groups that share no point (rule view_matches
matches each shot with its nearest shots only, which split two captures of ten in two), one
held frame fixes its own group only: each other group is put back where Eq. 6 places it
relative to the held one (:func:`shot_groups`, :func:`place_groups`; refine.json's
``shot_groups`` and a warning say so). What it may change of
registration B's rig is ``refine.rig`` (:data:`RIG_MODES`):

``hold``
    nothing: the sensors keep B's poses bit for bit, and their metric baselines fix the
    scale of the result, independently of Eq. 5;
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
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.rig import RigB
from plenocal.artifacts.tracks import SOURCES_OF
from plenocal.calib.central_tracks import TrackSet, joined
from plenocal.calib.groups import Groups
from plenocal.calib.reg_a import colmap as cm
from plenocal.calib.reg_a import viewdb
from plenocal.calib.scale import array_step_scale
from plenocal.calib.track_alignment import AlignSettings
from plenocal.calib.view_greys import ViewGreys, grey_of
from plenocal.camera import PinholeCamera, invert_pose, k_to_colmap, pose, rotation_angle_deg
from plenocal.config import settings_from, stage_defaults
from plenocal.names import split_key

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


# --- the COLMAP boundary -------------------------------------------------------------


def rigid3d(M: np.ndarray):
    """A 4x4 (or 3x4) rigid transform as a ``pycolmap.Rigid3d`` (rotation re-orthonormalised
    by SVD, as :func:`plenocal.calib.reg_a.colmap._rigid` does)."""
    import pycolmap  # noqa: PLC0415

    M = np.asarray(M, dtype=float)
    U, _, Vt = np.linalg.svd(M[:3, :3])
    return pycolmap.Rigid3d(pycolmap.Rotation3d(U @ Vt), M[:3, 3].copy())


def _camera_sensor(camera_id: int):
    import pycolmap  # noqa: PLC0415

    return pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=int(camera_id))


def _colmap_params(K: np.ndarray) -> list[float]:
    Kc = k_to_colmap(K)
    return [float(Kc[0, 0]), float(Kc[1, 1]), float(Kc[0, 2]), float(Kc[1, 2])]


@dataclass
class RigModel:
    """The rig reconstruction's bookkeeping: sensor camera ids by view, frame ids by shot,
    the reference (central) view."""

    camera_of_view: dict[str, int]
    frame_of_shot: dict[str, int]
    central: str


def rig_reconstruction(tracks, views: Mapping[str, tuple[np.ndarray, np.ndarray]],
                       shot_poses: Mapping[str, np.ndarray], width: int, height: int,
                       point_ids: list[int], work_dir: str | Path | None = None,
                       keypoints: Mapping[str, np.ndarray] | None = None):
    """A ``pycolmap.Reconstruction`` of one rig (``views``: view -> (K, cam_to_central), the
    central view the one whose pose is the identity) with one frame per shot
    (``shot_poses``: shot -> its central view's cam_to_world), every image of ``tracks``
    (a reconstruction triangulated with the same cameras, images named ``<shot>/<view>.png``)
    in its frame, and the points ``point_ids`` of ``tracks`` with their tracks. Each
    image's keypoints are read through ``tracks``'s binary files (written under
    ``work_dir``): the same numbers as through the bindings, whose per-point objects took
    1.9 s for 700 views of 1,300 keypoints; or given (``keypoints``: image name -> (n, 2),
    COLMAP's convention, the aligned ones of :func:`aligned_keypoints`). Returns the
    reconstruction and its :class:`RigModel`."""
    ts = track_set_of(tracks, point_ids, work_dir, keypoints)
    return rig_reconstruction_of(ts.names, ts.points, ts.keypoints, views, shot_poses, width,
                                 height)


def track_set_of(tracks, point_ids: list[int], work_dir: str | Path | None = None,
                 keypoints: Mapping[str, np.ndarray] | None = None) -> TrackSet:
    """The points ``point_ids`` of the reconstruction ``tracks`` as plain data: every image
    of ``tracks`` by its id, its keypoints (read through ``tracks``'s binary files under
    ``work_dir`` where ``keypoints`` is None, as :func:`rig_reconstruction` says) and the
    points with their tracks, in the order of ``point_ids``."""
    from plenocal.verify.reprojection import read_keypoints  # noqa: PLC0415

    if keypoints is None:
        keypoints = read_keypoints(tracks, work_dir)
    names = {image_id: tracks.image(image_id).name for image_id in sorted(tracks.images)}
    points = {}
    for pid in point_ids:
        p = tracks.point3D(pid)
        points[pid] = (p.xyz, [(e.image_id, e.point2D_idx) for e in p.track.elements])
    return TrackSet(names, dict(keypoints), points, int(tracks.num_points3D()))


def rig_reconstruction_of(image_names: Mapping[int, str],
                          points: Mapping[int, tuple[np.ndarray, list[tuple[int, int]]]],
                          keypoints: Mapping[str, np.ndarray],
                          views: Mapping[str, tuple[np.ndarray, np.ndarray]],
                          shot_poses: Mapping[str, np.ndarray], width: int, height: int):
    """:func:`rig_reconstruction` of plain data: ``image_names`` image id ->
    ``<shot>/<view>.png``, ``points`` point id -> (X, its track's (image id, keypoint index)
    pairs), added in the mapping's order, ``keypoints`` image name -> (n, 2) COLMAP's convention
    (:class:`plenocal.calib.central_tracks.TrackSet` holds the three)."""
    import pycolmap  # noqa: PLC0415

    names = sorted(views)
    central = identity_view(views)
    rec = pycolmap.Reconstruction()
    cam_of = {v: i + 1 for i, v in enumerate(names)}
    for v in names:
        rec.add_camera(pycolmap.Camera(model="PINHOLE", width=int(width), height=int(height),
                                       params=_colmap_params(views[v][0]),
                                       camera_id=cam_of[v]))
    rig = pycolmap.Rig(rig_id=1)
    rig.add_ref_sensor(_camera_sensor(cam_of[central]))
    for v in names:
        if v != central:
            rig.add_sensor(_camera_sensor(cam_of[v]), rigid3d(invert_pose(views[v][1])))
    rec.add_rig(rig)
    images = {}
    for image_id in sorted(image_names):
        name = image_names[image_id]
        shot, view = split_key(name[:-4])
        if shot not in shot_poses or view not in cam_of:
            raise ValueError(f"{name}: not a view of the rig's shots")
        images[image_id] = (shot, view, name)
    shots = sorted(shot_poses)
    frame_of = {s: i + 1 for i, s in enumerate(shots)}
    for s in shots:
        frame = pycolmap.Frame(frame_id=frame_of[s], rig_id=1)
        frame.rig_from_world = rigid3d(invert_pose(shot_poses[s]))
        for image_id, (shot, view, _) in images.items():
            if shot == s:
                frame.add_data_id(pycolmap.data_t(sensor_id=_camera_sensor(cam_of[view]),
                                                  id=image_id))
        rec.add_frame(frame)
    for image_id, (shot, view, name) in images.items():
        new = pycolmap.Image(name=name, keypoints=keypoints[name],
                             camera_id=cam_of[view], image_id=image_id)
        new.frame_id = frame_of[shot]
        rec.add_image(new)
    for s in shots:
        rec.register_frame(frame_of[s])
    for xyz, elements in points.values():
        track = pycolmap.Track()
        for image_id, idx in elements:
            track.add_element(int(image_id), int(idx))
        rec.add_point3D(np.asarray(xyz, float), track)
    return rec, RigModel(cam_of, frame_of, central)


def select_points(tracks, max_points: int) -> list[int]:
    """At most ``max_points`` of the points of ``tracks`` seen in three or more images:
    every k-th in id order (deterministic), k the smallest that keeps within the limit."""
    ids = sorted(pid for pid in tracks.point3D_ids() if tracks.point3D(pid).track.length() >= 3)
    stride = max(1, math.ceil(len(ids) / max_points))
    return ids[::stride]


def aligned_keypoints(tracks, point_ids: list[int], images: Mapping[str, str | Path],
                      settings: AlignSettings, num_threads: int,
                      work_dir: str | Path | None = None
                      ) -> tuple[dict[str, np.ndarray], dict]:
    """Every image's keypoints of ``tracks`` (image name -> (n, 2), COLMAP's convention),
    those observing the points ``point_ids`` aligned to their track's reference observation
    by their patches (:mod:`plenocal.calib.track_alignment`), with its statistics.
    ``images``: view key (``<shot>/<view>``) -> the view's image file."""
    from plenocal.calib import track_alignment as ta  # noqa: PLC0415
    from plenocal.verify.reprojection import read_keypoints  # noqa: PLC0415

    keypoints = read_keypoints(tracks, work_dir)
    name_of = {i: tracks.image(i).name for i in tracks.images}
    by_id = {i: keypoints[n] for i, n in name_of.items()}
    cameras = {}
    for i in name_of:
        im = tracks.image(i)
        T = im.cam_from_world().matrix()
        cameras[i] = (tracks.camera(im.camera_id).calibration_matrix(), T[:, :3], T[:, 3])
    points = {}
    for pid in point_ids:
        p = tracks.point3D(pid)
        points[pid] = (np.asarray(p.xyz, float),
                       [(e.image_id, e.point2D_idx) for e in p.track.elements])
    missing = sorted({name_of[i][:-4] for i in name_of} - set(images))
    if missing:
        raise ValueError(f"refine.align: no image file for {len(missing)} views "
                         f"({', '.join(missing[:5])}): rerun the conversion")

    def load(i: int) -> np.ndarray:
        return grey_of(images, name_of[i][:-4])

    t0 = time.perf_counter()
    obs, rows = ta.track_observations(points, cameras, by_id)
    uv, aligned, stats = ta.align_observations(obs, load, settings, num_threads)
    out = {n: kp.copy() for n, kp in keypoints.items()}
    rows = np.asarray(rows).reshape(-1, 2)
    for i, sel in ta.rows_of(rows[:, 0]).items():
        out[name_of[i]][rows[sel, 1]] = uv[sel]
    log.info("observations aligned by their patches: %d of %d (median shift %s px, %.1f s)",
             stats["aligned"], stats["observations"],
             "-" if stats["shift_median_px"] is None else f"{stats['shift_median_px']:.3f}",
             time.perf_counter() - t0)
    return out, stats


def cameras_of(rec) -> dict[str, PinholeCamera]:
    """Every image of a rig reconstruction -> its camera (internal convention)."""
    out = {}
    for image_id in sorted(rec.images):
        im = rec.image(image_id)
        out[im.name[:-4]] = cm.pinhole_from_colmap(im, rec.camera(im.camera_id))
    return out


def observation_errors(rec, work_dir: str | Path | None = None) -> np.ndarray:
    """Reprojection error (px) of every observation of ``rec``'s points, in the internal
    convention (read back through COLMAP's binary files, as Table I reads them)."""
    from plenocal.verify import reprojection as rp  # noqa: PLC0415

    obs, ids, xyz = rp.read_model(rec, work_dir)
    cams = cameras_of(rec)
    errs = [np.linalg.norm(cams[name[:-4]].project(xyz[rows])[0] - uv, axis=1)
            for name, rows, uv in rp.image_observations(obs, ids, sorted(obs))]
    return np.concatenate(errs) if errs else np.zeros(0)


def _loss(name: str):
    import pycolmap  # noqa: PLC0415

    return getattr(pycolmap.LossFunctionType, name.upper())


def _adjustment_setup(rec, model: RigModel, settings: RefineSettings, *, refine_focal: bool,
                      refine_rig: bool, hold_frame: str, loss_scale_px: float,
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


def focal_pass_std(rec, model: RigModel, settings: RefineSettings, *, refine_rig: bool,
                   hold_frame: str, loss_scale_px: float,
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


def bundle_adjust(rec, model: RigModel, settings: RefineSettings, *, refine_focal: bool,
                  refine_rig: bool, hold_frame: str, loss_scale_px: float,
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


def frame_centres(rec, model: RigModel) -> dict[str, np.ndarray]:
    """Each shot's rig (central view) centre, world coordinates (:func:`frame_poses`)."""
    return {shot: M[:3, 3] for shot, M in frame_poses(rec, model).items()}


def spread(centres: Mapping[str, np.ndarray]) -> float:
    """RMS distance of the centres from their mean: the array's size."""
    P = np.array([centres[k] for k in sorted(centres)])
    return float(np.sqrt(((P - P.mean(axis=0)) ** 2).sum(axis=1).mean()))


def frame_poses(rec, model: RigModel) -> dict[str, np.ndarray]:
    """Each shot's rig (central view) cam_to_world, world coordinates."""
    out = {}
    for shot, fid in model.frame_of_shot.items():
        M = np.eye(4)
        M[:3, :] = np.asarray(rec.frame(fid).rig_from_world.matrix(), dtype=float)
        out[shot] = invert_pose(M)
    return out


def shot_groups(ties: list[frozenset[str]], shots: Iterable[str]) -> list[list[str]]:
    """The shots as the points ``ties`` (:func:`point_shots`) tie them: two shots are in
    one group where a chain of points links them. Several groups where the matches leave
    them apart (rule view_matches pairs each shot with its nearest shots only, which can
    split the array in two): then no point fixes where one group lies relative to another.
    Each group sorted, the groups by their first shot."""
    groups = Groups(shots)
    for seen in ties:
        first, *rest = sorted(seen)
        for other in rest:
            groups.join(other, first)
    return groups.groups()


def point_shots(rec, model: RigModel) -> list[frozenset[str]]:
    """The shots that see each of the adjustment's points (those seen by two or more: the
    points that tie shots together)."""
    shot_of_frame = {fid: shot for shot, fid in model.frame_of_shot.items()}
    # each image's shot looked up once, not once per observation (1.2 million on the
    # default data: 2.6 -> 1.2 s, the same sets)
    shot_of_image = {i: shot_of_frame[rec.image(i).frame_id] for i in rec.images}
    out = []
    for pid in rec.point3D_ids():
        seen = frozenset(shot_of_image[el.image_id] for el in rec.point3D(pid).track.elements)
        if len(seen) > 1:
            out.append(seen)
    return out


def shot_ties(ties: list[frozenset[str]], shots: list[str],
              to: set[str] | None = None) -> dict[str, int]:
    """Per shot of ``shots``, how many of the points ``ties`` (:func:`point_shots`) it
    shares with another shot, or with one of the shots ``to``: the points that tie its
    pose to them (a shot whose points are its own only is held by nothing but the loss and
    the solver's steps)."""
    out = dict.fromkeys(shots, 0)
    for seen in ties:
        for shot in seen:
            if shot in out and (seen - {shot}) & (seen if to is None else to):
                out[shot] += 1
    return out


def place_groups(rec, model: RigModel, eq6_poses: Mapping[str, np.ndarray],
                 groups: list[list[str]], hold_shot: str) -> dict[str, float]:
    """Put every group of shots (:func:`shot_groups`) that the held shot's does not hold
    where Eq. 6 puts it relative to that group: the gauge of the adjustment is one rigid
    motion per group (the rig, shared by all, fixes one scale for all), and the held frame
    fixes only its own group's; the others drift along theirs as the solver's steps take
    them (on a capture of the wide geometry, 6.7 mm along the views' axes while the rig's
    baselines rescaled the array by 1.7 %). The similarity that best maps the held group's
    Eq. 6 poses onto its adjusted ones (:func:`plenocal.verify.gt_errors.pose_similarity`)
    carries Eq. 6's other poses into the adjustment's frame; each other group, frames and
    points, is moved by the rigid motion that best fits it onto them (which leaves every
    reprojection as it is). Returns each moved group's correction (mm, largest centre
    move) by its first shot."""
    from plenocal.verify.gt_errors import pose_similarity  # noqa: PLC0415

    ref = next(g for g in groups if hold_shot in g)
    now = frame_poses(rec, model)

    def fit(shots, src, dst, with_scale):
        return pose_similarity(np.array([src[k][:3, 3] for k in shots]),
                               np.array([dst[k][:3, 3] for k in shots]),
                               [src[k][:3, :3] for k in shots],
                               [dst[k][:3, :3] for k in shots], with_scale=with_scale)

    s, R, t = fit(ref, eq6_poses, now, len(ref) > 1)
    target = {k: pose(R @ M[:3, :3], s * R @ M[:3, 3] + t) for k, M in eq6_poses.items()}
    moved = {}
    for group in groups:
        if group is ref:
            continue
        _, Rg, tg = fit(group, now, target, False)
        G = pose(Rg, tg)
        for shot in group:
            rec.frame(model.frame_of_shot[shot]).rig_from_world = rigid3d(
                invert_pose(G @ now[shot]))
        frames = {model.frame_of_shot[k] for k in group}
        for pid in rec.point3D_ids():
            p = rec.point3D(pid)
            if rec.image(p.track.elements[0].image_id).frame_id in frames:
                p.xyz = Rg @ np.asarray(p.xyz, dtype=float) + tg
        moved[group[0]] = 1000.0 * max(float(np.linalg.norm(G[:3, :3] @ now[k][:3, 3] + tg
                                                            - now[k][:3, 3])) for k in group)
    return moved


def rescale(rec, factor: float) -> None:
    """Scale ``rec`` by ``factor`` about the world origin: its points, its frames and its
    rig's sensor translations (COLMAP's ``Reconstruction.transform`` scales all three), a
    gauge of the adjustment wherever the rig's size is not held."""
    import pycolmap  # noqa: PLC0415

    rec.transform(pycolmap.Sim3d(float(factor), pycolmap.Rotation3d(), np.zeros(3)))


def sensor_params(rec) -> dict[int, np.ndarray]:
    """The rig's sensor_from_rig parameters (quaternion xyzw, translation) by camera id."""
    rig = rec.rig(1)
    return {s.id: np.asarray(rig.sensor_from_rig(s).params, dtype=float).copy()
            for s in rig.non_ref_sensors}


def shared_focal(rec, model: RigModel) -> tuple[float, dict[str, float]]:
    """The mean of the sensors' focal lengths (fx, fy) weighted by their observations,
    and each sensor's."""
    counts = {cid: 0 for cid in model.camera_of_view.values()}
    for image_id in rec.images:
        im = rec.image(image_id)
        counts[im.camera_id] += im.num_points3D
    per = {v: 0.5 * float(rec.camera(cid).params[0] + rec.camera(cid).params[1])
           for v, cid in model.camera_of_view.items()}
    w = np.array([counts[model.camera_of_view[v]] for v in sorted(per)], dtype=float)
    f = np.array([per[v] for v in sorted(per)])
    if w.sum() <= 0:
        raise ValueError("refinement: no sensor has an observation")
    return float((w * f).sum() / w.sum()), per


def set_intrinsics(rec, model: RigModel, views: Mapping[str, tuple[np.ndarray, np.ndarray]],
                   offsets: Mapping[str, np.ndarray] | None = None) -> None:
    """Each sensor's camera as ``views`` gives it (registration B's K); with ``offsets``
    (view -> (dx, dy) px), its principal point moved by them."""
    for v, cid in model.camera_of_view.items():
        params = _colmap_params(views[v][0])
        if offsets is not None:
            params[2] += float(offsets[v][0])
            params[3] += float(offsets[v][1])
        rec.camera(cid).params = params


def principal_points(rec, model: RigModel) -> dict[str, np.ndarray]:
    """Each view's principal point (COLMAP's pixel convention), px."""
    return {v: np.array(rec.camera(cid).params[2:4], dtype=float)
            for v, cid in model.camera_of_view.items()}


def turn_of_shift(shift_px: np.ndarray, focal_px: float) -> np.ndarray:
    """The turn of a camera (3 x 3, applied to camera coordinates: x right, y down, z
    forward) that moves its image as the shift ``shift_px`` = (dx, dy) of its principal
    point does, exactly at the image centre, to first order elsewhere: the least rotation
    that takes the optical axis to the direction (dx / f, dy / f, 1), about the axis
    (-dy, dx, 0) by ``atan(|shift| / f)`` (Rodrigues' formula)."""
    d = np.asarray(shift_px, dtype=float)
    norm = float(np.hypot(d[0], d[1]))
    if norm == 0.0:
        return np.eye(3)
    k = np.array([-d[1], d[0], 0.0]) / norm
    angle = math.atan(norm / focal_px)
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * Kx + (1.0 - math.cos(angle)) * (Kx @ Kx)


def turn_frames(rec, model: RigModel, turn: np.ndarray, hold_shot: str) -> None:
    """Turn every frame of ``rec`` by ``turn`` in its own (rig) axes, and the world about
    the held shot's rig so that its frame keeps its pose: with ``H`` the held frame's
    rig_from_world, the points go to ``T p`` with ``T = H^-1 R H`` and each frame's
    rig_from_world ``F`` to ``R F T^-1`` (for the held one ``H`` again). What every frame
    sees moves as if each view's principal point had moved by the shift of
    :func:`turn_of_shift`: the common shift of the focal pass taken back into the frames
    (:func:`warm_start`)."""
    R4 = np.eye(4)
    R4[:3, :3] = turn
    H = np.eye(4)
    H[:3, :] = np.asarray(rec.frame(model.frame_of_shot[hold_shot]).rig_from_world.matrix(),
                          dtype=float)
    T = invert_pose(H) @ R4 @ H
    A, b = T[:3, :3], T[:3, 3]
    for pid in rec.point3D_ids():
        point = rec.point3D(pid)
        point.xyz = A @ np.asarray(point.xyz, dtype=float) + b
    T_inv = invert_pose(T)
    for fid in sorted(model.frame_of_shot.values()):
        F = np.eye(4)
        F[:3, :] = np.asarray(rec.frame(fid).rig_from_world.matrix(), dtype=float)
        rec.frame(fid).rig_from_world = rigid3d(R4 @ F @ T_inv)


def set_rig(rec, model: RigModel, views: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> None:
    rig = rec.rig(1)
    for v, cid in model.camera_of_view.items():
        if v != model.central:
            rig.set_sensor_from_rig(_camera_sensor(cid), rigid3d(invert_pose(views[v][1])))


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
    :func:`make_track_set`), or a function that reads them (rule ``refine``: then no
    reference outlives the rig reconstruction); the databases and images are not read."""
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
        ts, align, t_tri = _view_tracks(eq6, database, settings, images, align_threads,
                                        work_dir)
    else:
        ts, align, t_tri = _central_tracks(eq6, central, database, settings, images,
                                           align_threads, work_dir)
    if settings.tracks == "both":
        ts_views, align_views, t_views = _view_tracks(eq6, view_database, settings, images,
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


def track_sources(settings: RefineSettings) -> tuple[str, ...]:
    """The track sets ``settings.tracks`` adjusts, in the order they are joined
    (:data:`plenocal.artifacts.tracks.SOURCES_OF`)."""
    return SOURCES_OF[settings.tracks]


def identity_view(views: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> str:
    """The rig's view at the identity pose, its central view (``views``:
    :meth:`RigB.view_poses`; by pose, where :func:`plenocal.names.central_view` names it by
    the grid's size)."""
    central = [v for v in views if np.allclose(views[v][1], np.eye(4), atol=1e-12)]
    if len(central) != 1:
        raise ValueError("the rig has no view at the identity pose (its central view): "
                         "rerun rule rig_b")
    return central[0]


def make_track_set(source: str, eq6: Mapping[str, PinholeCamera], rig: RigB,
                   database: str | Path, settings: RefineSettings,
                   images: Mapping[str, str | Path] | None,
                   align_threads: int | None = None,
                   work_dir: str | Path | None = None) -> tuple[TrackSet, dict, float]:
    """One track set of the refinement (rule ``refine_tracks``), as
    :func:`refine_calibration` makes it for ``source``: ``central`` the central views'
    matches (``database``: rule match_central's) carried into every view, ``views`` every
    view's matches (rule view_matches'); triangulated with the Eq. 6 cameras ``eq6`` and
    aligned by the views' patches (``images``). Returns the set, its alignment's
    statistics and its triangulation's seconds (the central views' set: all its
    seconds)."""
    if source == "views":
        return _view_tracks(eq6, database, settings, images, align_threads, work_dir)
    if source == "central":
        return _central_tracks(eq6, identity_view(rig.view_poses()), database, settings,
                               images, align_threads, work_dir)
    raise ValueError(f"track set source {source!r}: use central or views")


#: a track set made beforehand and its alignment's statistics, or a function that reads
#: them (:func:`refine_calibration`'s ``track_sets``)
TrackSource = tuple[TrackSet, dict] | Callable[[], tuple[TrackSet, dict]]

#: the remedy where a track source gives too few points
_TOO_FEW = {
    "views": "the views have too few matches: see matches/matches.json",
    "central": "of the central views' matches; set refine.tracks: views or both (with the "
               "matches of every view)",
    "both": "the central views' and every view's matches together; see "
            "matches/matches.json",
}


def _central_tracks(eq6: Mapping[str, PinholeCamera], central: str, database: str | Path,
                    settings: RefineSettings, images: Mapping[str, str | Path] | None,
                    align_threads: int | None, work_dir: str | Path | None
                    ) -> tuple[TrackSet, dict, float]:
    """The tracks of the central views' matches (``database``, rule match_central's),
    carried into the other views (:mod:`plenocal.calib.central_tracks`), at most
    ``settings.max_points`` of them (every k-th point id); their alignment's statistics
    and the time taken."""
    from plenocal.calib.central_tracks import central_track_set  # noqa: PLC0415

    if images is None:
        raise ValueError(f"refine.tracks {settings.tracks} carries the central views' points "
                         "into the other views by their pixels: the views' images are needed")
    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="plenocal_refine_", dir=work_dir))
    try:
        ts, stats = central_track_set(database, eq6, central, images, settings, tmp,
                                      align_threads)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    ids = sorted(ts.points)
    ids = ids[::max(1, math.ceil(len(ids) / settings.max_points))]
    kept = TrackSet(ts.names, ts.keypoints, {pid: ts.points[pid] for pid in ids},
                    ts.triangulated)
    return kept, {"enabled": True, **stats}, time.perf_counter() - t0


def _view_tracks(eq6: Mapping[str, PinholeCamera], database: str | Path,
                 settings: RefineSettings, images: Mapping[str, str | Path] | None,
                 align_threads: int | None, work_dir: str | Path | None
                 ) -> tuple[TrackSet, dict, float]:
    """The tracks of the verified matches of every view (``database``, rule view_matches'),
    triangulated with the Eq. 6 cameras, at most ``settings.max_points`` of them
    (:func:`select_points`), their observations aligned by their patches where
    ``settings.align`` says so and the images are given; the alignment's statistics and
    the triangulation's time."""
    from plenocal.verify import reprojection as rp  # noqa: PLC0415

    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="plenocal_refine_", dir=work_dir))
    try:
        db = tmp / "database.db"
        names = sorted(eq6)
        across = None
        if settings.matches == "across":
            def across(a: str, b: str) -> bool:
                return split_key(a)[0] != split_key(b)[0]
        viewdb.subset_database(database, db, names, dict(eq6), keep_pair=across)
        colmap_cams = {f"{k}.png": eq6[k] for k in names}
        tracks = cm.known_pose_reconstruction(db, colmap_cams, update_intrinsics=False)
        opts = rp.triangulation_options(settings.max_error_px, settings.min_angle_deg,
                                        settings.seed, settings.num_threads)
        rp.triangulate(tracks, db, opts, settings.seed, colmap_cams, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    t_tri = time.perf_counter() - t0
    ids = select_points(tracks, settings.max_points)
    keypoints, align = None, {"enabled": False}
    if settings.align.enabled and images is not None and ids:
        keypoints, stats = aligned_keypoints(
            tracks, ids, images, settings.align,
            settings.num_threads if align_threads is None else align_threads, work_dir)
        align = {"enabled": True, **stats}
    elif settings.align.enabled:
        align["why"] = "no view images given: the observations are SIFT's keypoints"
    return track_set_of(tracks, ids, work_dir, keypoints), align, t_tri


def warm_start(rec, model: RigModel, views: Mapping[str, tuple[np.ndarray, np.ndarray]],
               settings: RefineSettings, focal: float, hold_shot: str) -> float:
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
    b = {v: np.array(_colmap_params(views[v][0])[2:4]) for v in model.camera_of_view}
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


def _adjusted(rec, model: RigModel, eq6, rig: RigB, views, shots, central, shot_poses,
              settings: RefineSettings, *, hold_shot, rig_at_focal, step_m, points, align,
              t0, t_tri, work_dir) -> Refinement:
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
                     else {v: (_with_focal(K, focal), M) for v, (K, M) in views.items()})
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


def refined_step_scale(rec, model: RigModel, step_m: float) -> dict | None:
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
    return "Eq. 5 (the result scaled to Eq. 6's spread, the rig with it)"


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
    refined ones (the gauge), and whether that is to be trusted.

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


def _with_focal(K: np.ndarray, focal: float) -> np.ndarray:
    out = np.array(K, dtype=float)
    out[0, 0] = out[1, 1] = focal
    return out


def rig_views_from_model(rec, model: RigModel) -> dict[str, np.ndarray]:
    """The rig's sensors as cam_to_central (internal), by view."""
    rig = rec.rig(1)
    out = {model.central: np.eye(4)}
    for v, cid in model.camera_of_view.items():
        if v != model.central:
            M = np.eye(4)
            M[:3, :] = np.asarray(rig.sensor_from_rig(_camera_sensor(cid)).matrix(), dtype=float)
            out[v] = invert_pose(M)
    return out



def rig_views_from_cameras(cameras: Mapping[str, PinholeCamera], shot: str,
                           central: str | None = None) -> dict[str, np.ndarray]:
    """The rig as a calibration places one shot's views: view -> cam_to_central (the
    central view ``central``, by default the middle of the shot's N x N names)."""
    names = sorted(split_key(k)[1] for k in cameras if split_key(k)[0] == shot)
    if not names:
        raise ValueError(f"no view of shot {shot}")
    c = central or names[len(names) // 2]
    inv = invert_pose(cameras[f"{shot}/{c}"].cam_to_world)
    return {v: inv @ cameras[f"{shot}/{v}"].cam_to_world for v in names}
