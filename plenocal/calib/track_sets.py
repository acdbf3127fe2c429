"""The joint refinement's points (:mod:`plenocal.calib.refine`): the track sets made from
the matches (rule ``refine_tracks``, :func:`make_track_set`), one per source of
``refine.tracks`` (:func:`track_sources`):

* ``central``: the central views' matches (rule ``match_central``) triangulated with the
  Eq. 6 cameras held fixed and carried into each shot's other views by their patches
  (:mod:`plenocal.calib.central_tracks`);
* ``views``: the verified matches of every view (rule ``view_matches``, the matches
  Table I triangulates) triangulated the same way
  (:func:`plenocal.verify.reprojection.triangulate`), their observations aligned by their
  patches to their track's reference observation (``refine.align``,
  :mod:`plenocal.calib.track_alignment`: :func:`aligned_keypoints`).

At most ``refine.max_points`` points a set, every k-th by id (:func:`select_points`).
"""

from __future__ import annotations

import logging
import math
import shutil
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from plenocal.artifacts.rig import RigB
from plenocal.artifacts.tracks import SOURCES_OF
from plenocal.calib.central_tracks import TrackSet
from plenocal.calib.reg_a import colmap as cm
from plenocal.calib.reg_a import viewdb
from plenocal.calib.rig_model import RigModel, identity_view, rig_reconstruction_of
from plenocal.calib.track_alignment import AlignSettings
from plenocal.calib.view_greys import grey_of
from plenocal.camera import PinholeCamera
from plenocal.names import split_key

if TYPE_CHECKING:
    from pycolmap import Reconstruction

    from plenocal.calib.refine import RefineSettings

# the refinement's logger: the track sets' lines read as the step's own, as they did
# before this module was split off refine.py
log = logging.getLogger("plenocal.calib.refine")


def rig_reconstruction(tracks: Reconstruction, views: Mapping[str, tuple[np.ndarray, np.ndarray]],
                       shot_poses: Mapping[str, np.ndarray], width: int, height: int,
                       point_ids: list[int], work_dir: str | Path | None = None,
                       keypoints: Mapping[str, np.ndarray] | None = None
                       ) -> tuple[Reconstruction, RigModel]:
    """A ``pycolmap.Reconstruction`` of one rig (``views``: view -> (K, cam_to_central), the
    central view the one whose pose is the identity) with one frame per shot
    (``shot_poses``: shot -> its central view's cam_to_world), every image of ``tracks``
    (a reconstruction triangulated with the same cameras, images named ``<shot>/<view>.png``)
    in its frame, and the points ``point_ids`` of ``tracks`` with their tracks. Each
    image's keypoints are read through ``tracks``'s binary files (written under
    ``work_dir``): the same numbers as through the bindings, whose per-point objects took
    1.9 s for 700 views of 1,300 keypoints; or given (``keypoints``: image name -> (n, 2),
    COLMAP's convention, the aligned ones of :func:`aligned_keypoints`). Returns the
    reconstruction and its :class:`~plenocal.calib.rig_model.RigModel`."""
    ts = track_set_of(tracks, point_ids, work_dir, keypoints)
    return rig_reconstruction_of(ts.names, ts.points, ts.keypoints, views, shot_poses, width,
                                 height)


def track_set_of(tracks: Reconstruction, point_ids: list[int], work_dir: str | Path | None = None,
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


def select_points(tracks: Reconstruction, max_points: int) -> list[int]:
    """At most ``max_points`` of the points of ``tracks`` seen in three or more images:
    every k-th in id order (deterministic), k the smallest that keeps within the limit."""
    ids = sorted(pid for pid in tracks.point3D_ids() if tracks.point3D(pid).track.length() >= 3)
    stride = max(1, math.ceil(len(ids) / max_points))
    return ids[::stride]


def aligned_keypoints(tracks: Reconstruction, point_ids: list[int],
                      images: Mapping[str, str | Path], settings: AlignSettings, num_threads: int,
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


def track_sources(settings: RefineSettings) -> tuple[str, ...]:
    """The track sets ``settings.tracks`` adjusts, in the order they are joined
    (:data:`plenocal.artifacts.tracks.SOURCES_OF`)."""
    return SOURCES_OF[settings.tracks]


def make_track_set(source: str, eq6: Mapping[str, PinholeCamera], rig: RigB,
                   database: str | Path, settings: RefineSettings,
                   images: Mapping[str, str | Path] | None,
                   align_threads: int | None = None,
                   work_dir: str | Path | None = None) -> tuple[TrackSet, dict, float]:
    """One track set of the refinement (rule ``refine_tracks``), as
    :func:`~plenocal.calib.refine.refine_calibration` makes it for ``source``: ``central``
    the central views' matches (``database``: rule match_central's) carried into every
    view, ``views`` every view's matches (rule view_matches'); triangulated with the Eq. 6
    cameras ``eq6`` and aligned by the views' patches (``images``). Returns the set, its alignment's
    statistics and its triangulation's seconds (the central views' set: all its
    seconds)."""
    if source == "views":
        return tracks_of_every_view(eq6, database, settings, images, align_threads, work_dir)
    if source == "central":
        return tracks_of_central_views(eq6, identity_view(rig.view_poses()), database, settings,
                               images, align_threads, work_dir)
    raise ValueError(f"track set source {source!r}: use central or views")


#: a track set made beforehand and its alignment's statistics, or a function that reads
#: them (:func:`~plenocal.calib.refine.refine_calibration`'s ``track_sets``)
TrackSource = tuple[TrackSet, dict] | Callable[[], tuple[TrackSet, dict]]


def tracks_of_central_views(eq6: Mapping[str, PinholeCamera], central: str, database: str | Path,
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


def tracks_of_every_view(eq6: Mapping[str, PinholeCamera], database: str | Path,
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
