"""Reprojection error of a calibration, as in Table I of the paper (Section III):
triangulate the views' SIFT matches with every pose and intrinsic held fixed, and
measure how far the triangulated points reproject from their keypoints. Every
calibration is measured on the same verified matches, those of the view database
(:mod:`plenocal.calib.reg_a.viewdb`), each view with a camera of its own set to the
calibration's intrinsics.

COLMAP's point triangulator drops observations that reproject farther than 4 px
(``filter_max_reproj_error``): a calibration that is off then looks good because its
bad observations are gone. That filter is raised (``max_error_px``, 100 px by default)
so that the figure is honest. The thresholds that grow tracks by merging and completing
them (``merge/complete_max_reproj_error``) stay at COLMAP's 4 px (``track_error_px``):
raised as well, they chain mismatches into tracks hundreds of views long - on the
default data, with the true cameras, 6 % of the observations then lie beyond 4 px and
the mean is 1.40 px instead of 0.31 px (median 0.13 / 0.12 px), whatever the
calibration. Tracks are first built from each image's matches within COLMAP's angular
limits, so a calibration that is off still keeps its bad observations. The error is
recomputed here per observation in the internal convention (the keypoint minus 0.5 against
``PinholeCamera.project``), which also checks the COLMAP boundary conversion.

The triangulation is COLMAP's point triangulator (``TriangulateReconstruction``, run step
by step: every image triangulated, then rounds of track completion and merging,
retriangulation, bundle adjustment of the points, filtering) with one change: each new
track is completed as soon as it is created (``complete_tracks`` of the image's new points,
at ``track_error_px``), as COLMAP's incremental mapper does after every registered image,
instead of only at the end. The point triangulator alone leaves every physical point in
dozens of fragments - each image creates a point from its still untriangulated matches -
and merging them cost three quarters of each 700-view job (every merge re-links whole
tracks, and tracks here run to hundreds of views). Completed at once, the tracks need few
merges: a 700-view job took 233 CPU s, now 43 (BENCHMARKS.md). On the default data (the
same matches): the same observations to within 15 of 949 000, fewer 3-D points (19 192
against 20 458 with the complete calibration: fragments that had failed the all-inliers
merge test), and Table I's mean / median px: complete 0.4150 / 0.2022 -> 0.3975 / 0.2019,
A+SfM 0.4299 / 0.2235 -> 0.4101 / 0.2230 (proposed / naive 0.965 / 0.905 -> 0.969 /
0.906), true cameras 0.4126 / 0.2009 -> 0.3962 / 0.2007, registration A 0.2501 / 0.1174
-> 0.2611 / 0.1179, registration B 0.2673 / 0.1627 -> 0.2676 / 0.1628.

A second change: the bundle adjustments between the rounds of merging and filtering move
only the points (every pose and intrinsic is fixed), so they are solved point by point
(:mod:`plenocal.verify.point_refinement`, the same least squares as Ceres', to tighter
tolerances) instead of by Ceres as one sparse problem. On the default data, 700 views:
a calibration's job 31 -> 15 s; Table I's complete calibration 0.32281 / 0.15361 ->
0.32291 / 0.15362 px (tests/test_reprojection.py compares the points with COLMAP's own
adjustment).

Reported: the per-observation mean and median (and RMS, 90th percentile), COLMAP's own
mean (``compute_mean_reprojection_error``: a mean of per-track means, weighted
differently), and the numbers of images, observations and 3-D points.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import struct
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

import numpy as np

from plenocal.artifacts.cameras import read_cameras
from plenocal.artifacts.reg_a import RegistrationA, read_reg_a
from plenocal.artifacts.rig import RigB, read_rig
from plenocal.calib.reg_a import colmap as cm
from plenocal.calib.reg_a import viewdb
from plenocal.camera import PinholeCamera
from plenocal.names import is_handheld_shot, key_shot, view_key
from plenocal.verify import point_refinement

log = logging.getLogger(__name__)
_REPROJ = cm.SFM_DEFAULTS["reprojection"]  # the triangulation's defaults: the schema's


def triangulation_options(max_error_px: float, min_angle_deg: float, seed: int,
                          num_threads: int,
                          track_error_px: float = _REPROJ["track_error_px"]):
    """IncrementalPipelineOptions for triangulation with fixed poses: the observation
    filter at ``max_error_px``, track merging and completion at ``track_error_px``
    (module docstring)."""
    import pycolmap  # noqa: PLC0415

    o = pycolmap.IncrementalPipelineOptions()
    o.random_seed = seed
    o.num_threads = num_threads
    o.extract_colors = False
    o.ba_refine_focal_length = False
    o.ba_refine_principal_point = False
    o.ba_refine_extra_params = False
    o.fix_existing_frames = True  # as pycolmap.triangulate_points sets them
    o.load_all_images = True
    o.mapper.filter_max_reproj_error = max_error_px
    o.mapper.filter_min_tri_angle = min_angle_deg
    o.mapper.random_seed = seed
    t = o.triangulation
    t.merge_max_reproj_error = track_error_px
    t.complete_max_reproj_error = track_error_px
    t.min_angle = min_angle_deg
    t.random_seed = seed
    return o


_INVALID_POINT3D = np.uint64(2**64 - 1)
_OBSERVATION = np.dtype([("x", "<f8"), ("y", "<f8"), ("point3D_id", "<u8")])
_POINT_HEADER = struct.Struct("<Q3d3BdQ")  # id, xyz, rgb, error, track length


def read_observations(model_dir: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``images.bin`` of a COLMAP binary model -> ``{image name: (keypoints (n, 2) in
    COLMAP's convention, point3D ids (n,), uint64; 2**64 - 1 where none)}``."""
    buf = (Path(model_dir) / "images.bin").read_bytes()
    (n,) = struct.unpack_from("<Q", buf, 0)
    off, out = 8, {}
    for _ in range(n):
        off += 4 + 7 * 8 + 4  # image id, cam_from_world (q, t), camera id
        end = buf.index(b"\0", off)
        name = buf[off:end].decode()
        (k,) = struct.unpack_from("<Q", buf, end + 1)
        obs = np.frombuffer(buf, _OBSERVATION, k, end + 9)
        off = end + 9 + k * _OBSERVATION.itemsize
        out[name] = (np.stack([obs["x"], obs["y"]], axis=1), obs["point3D_id"])
    return out


def read_points(model_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``points3D.bin`` of a COLMAP binary model -> (sorted ids (n,), xyz (n, 3))."""
    buf = (Path(model_dir) / "points3D.bin").read_bytes()
    (n,) = struct.unpack_from("<Q", buf, 0)
    ids, xyz, off = np.empty(n, np.uint64), np.empty((n, 3)), 8
    for i in range(n):
        pid, x, y, z, _, _, _, _, length = _POINT_HEADER.unpack_from(buf, off)
        ids[i], xyz[i] = pid, (x, y, z)
        off += _POINT_HEADER.size + 8 * length
    order = np.argsort(ids, kind="stable")
    return ids[order], xyz[order]


def observation_errors(rec, cameras: Mapping[str, PinholeCamera],
                       work_dir: str | Path | None = None) -> np.ndarray:
    """Per-observation reprojection errors (pixels) of a triangulated reconstruction
    whose images are named as the keys of ``cameras``, computed in the internal
    convention: keypoint (COLMAP) - 0.5 against ``cameras[name].project``. Images in
    ascending id order, observations in keypoint order. The model is read back from
    COLMAP's binary files (a million observations: 0.5 s, against 17 s through the
    Python bindings)."""
    obs, ids, xyz = read_model(rec, work_dir)
    names = [rec.image(image_id).name for image_id in sorted(rec.reg_image_ids())]
    errs = [np.linalg.norm(cameras[name].project(xyz[rows])[0] - uv, axis=1)
            for name, rows, uv in image_observations(obs, ids, names)]
    return np.concatenate(errs) if errs else np.zeros(0)


def image_observations(obs: Mapping[str, tuple[np.ndarray, np.ndarray]], ids: np.ndarray,
                       names: Iterable[str]) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """The observations of a model read by :func:`read_model` (``obs``, point ``ids``),
    image by image in the order of ``names``: (name, each observation's row in ``ids``,
    its pixel in the internal convention: keypoint - 0.5); images without any are left
    out."""
    for name in names:
        kp, pid = obs[name]
        has = pid != _INVALID_POINT3D
        if has.any():
            yield name, np.searchsorted(ids, pid[has]), kp[has] - 0.5


def triangulate(rec, database: str | Path, options, seed: int,
                cameras: Mapping[str, PinholeCamera],
                work_dir: str | Path | None = None) -> None:
    """COLMAP's point triangulator with poses and intrinsics fixed
    (``TriangulateReconstruction`` as ``pycolmap.triangulate_points`` runs it, step by
    step), each new track completed as soon as it is created (module docstring).
    ``options``: :func:`triangulation_options`. ``rec``: a reconstruction of the
    database's images (their ids), those with a pose registered; its points are
    replaced."""
    import pycolmap  # noqa: PLC0415

    tri = options.get_triangulation()
    mapper_options = options.get_mapper()
    pycolmap.set_random_seed(seed)
    rec.delete_all_points2D_and_points3D()
    with pycolmap.Database.open(str(database)) as db:
        rec.transcribe_image_ids_to_database(db)
        cache_options = pycolmap.DatabaseCacheOptions()
        cache_options.min_num_matches = options.min_num_matches
        cache_options.ignore_watermarks = options.ignore_watermarks
        cache_options.load_all_images = True
        cache = pycolmap.DatabaseCache.create(db, cache_options)
    mapper = pycolmap.IncrementalMapper(cache)
    mapper.begin_reconstruction(rec)
    triangulator = mapper.triangulator
    last = 0  # point ids grow: those above ``last`` are new
    for image_id in rec.reg_image_ids():
        mapper.triangulate_image(tri, image_id)
        new = {p for p in triangulator.get_modified_points3D() if p > last}
        if new:
            triangulator.complete_tracks(tri, new)
            last = max(new)
        triangulator.clear_modified_points3D()
    global_refinement(mapper, rec, cameras, options, tri, mapper_options, work_dir)
    mapper.end_reconstruction(False)
    rec.update_point_3d_errors()


def global_refinement(mapper, rec, cameras: Mapping[str, PinholeCamera], options, tri,
                      mapper_options, work_dir: str | Path | None = None) -> None:
    """COLMAP's ``IterativeGlobalRefinement`` (complete and merge the tracks,
    retriangulate, then rounds of bundle adjustment, completion, merging and filtering
    until few observations change) with the bundle adjustment of the points solved by
    :func:`plenocal.verify.point_refinement.refine_points` (every camera is fixed: the
    module docstring there). ``cameras``: COLMAP image name -> PinholeCamera."""
    mapper.complete_and_merge_tracks(tri)
    mapper.retriangulate(tri)
    for _ in range(options.ba_global_max_refinements):
        num_observations = rec.compute_num_observations()
        # as COLMAP's AdjustGlobalBundle: no observation behind its camera
        mapper.observation_manager.filter_observations_with_negative_depth()
        adjust_points(rec, cameras, work_dir)
        changed = mapper.complete_and_merge_tracks(tri) + mapper.filter_points(mapper_options)
        if num_observations == 0 or (changed / num_observations
                                     < options.ba_global_max_refinement_change):
            break
    mapper.clear_modified_points3D()


def adjust_points(rec, cameras: Mapping[str, PinholeCamera],
                  work_dir: str | Path | None = None) -> int:
    """Every 3-D point of ``rec`` moved to the least squared reprojection error of its
    observations, the cameras (``cameras``: image name -> PinholeCamera) fixed. Returns the
    number of points."""
    obs, ids, xyz = read_model(rec, work_dir)
    seen = list(image_observations(obs, ids, sorted(obs)))
    if not seen:
        return 0
    P = np.stack([point_refinement.projection_matrices(cameras[n].K, cameras[n].world_to_cam)
                  for n, _, _ in seen])
    image = [np.full(len(rows), i) for i, (_, rows, _) in enumerate(seen)]
    refined, _ = point_refinement.refine_points(xyz, np.concatenate([r for _, r, _ in seen]),
                                                np.concatenate(image), P,
                                                np.concatenate([uv for _, _, uv in seen]))
    points = rec.points3D
    for pid, x in zip(ids.tolist(), refined, strict=True):
        points[pid].xyz = x
    return len(ids)


@contextlib.contextmanager
def written_model(rec, work_dir: str | Path | None = None) -> Iterator[Path]:
    """A temporary folder (under ``work_dir``) holding ``rec``'s binary files, removed
    after the block: COLMAP's files are read far faster than the Python bindings."""
    tmp = Path(tempfile.mkdtemp(prefix="plenocal_model_", dir=work_dir))
    try:
        rec.write_binary(str(tmp))
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def read_model(rec, work_dir: str | Path | None = None):
    """The observations (:func:`read_observations`) and the points (:func:`read_points`) of
    ``rec``, through its binary files (:func:`written_model`)."""
    with written_model(rec, work_dir) as folder:
        return (read_observations(folder), *read_points(folder))


def read_keypoints(rec, work_dir: str | Path | None = None) -> dict[str, np.ndarray]:
    """Every image's keypoints of ``rec`` (image name -> (n, 2) float64, COLMAP's
    convention, in the image's point order), through its binary files
    (:func:`written_model`, :func:`read_observations`)."""
    with written_model(rec, work_dir) as folder:
        return {name: kp for name, (kp, _) in read_observations(folder).items()}


def triangulated_stats(cameras: Mapping[str, PinholeCamera], database: str | Path, *,
                       max_error_px: float = _REPROJ["max_error_px"],
                       min_angle_deg: float = _REPROJ["min_angle_deg"],
                       track_error_px: float = _REPROJ["track_error_px"],
                       seed: int = cm.DEFAULT_SEED, num_threads: int = cm.DEFAULT_THREADS,
                       work_dir: str | Path | None = None, model_dir: str | Path | None = None,
                       images: Mapping[str, str | Path] | None = None) -> dict:
    """Reprojection error of the calibration ``cameras`` (``"<cam>/<view>"`` ->
    PinholeCamera) on the verified matches of the view ``database``
    (:mod:`plenocal.calib.reg_a.viewdb`): its images copied with one camera each set to the
    calibration, triangulation with poses and intrinsics fixed, then the statistics
    (module docstring). ``model_dir``: where the triangulated model is also written
    (:func:`write_points_model`; ``images``: view key -> its image file, the points'
    colours)."""
    if len(cameras) < 2:
        raise ValueError("reprojection error needs at least two views")
    tmp = Path(tempfile.mkdtemp(prefix="plenocal_reproj_", dir=work_dir))
    try:
        db = tmp / "database.db"
        n_pairs = viewdb.subset_database(database, db, sorted(cameras), dict(cameras))
        colmap_cams = {f"{k}.png": cameras[k] for k in cameras}
        rec = cm.known_pose_reconstruction(db, colmap_cams, update_intrinsics=False)
        opts = triangulation_options(max_error_px, min_angle_deg, seed, num_threads,
                                     track_error_px)
        triangulate(rec, db, opts, seed, colmap_cams, tmp)
        # poses and intrinsics must not have moved
        for image_id in rec.reg_image_ids():
            image = rec.image(image_id)
            got = cm.pinhole_from_colmap(image, rec.camera(image.camera_id))
            want = colmap_cams[image.name]
            if np.abs(got.cam_to_world - want.cam_to_world).max() > 1e-6 * max(
                    1.0, np.abs(want.cam_to_world[:3, 3]).max()):
                raise RuntimeError(f"{image.name}: the triangulation moved a fixed pose")
            if np.abs(got.K - want.K).max() > 1e-6:
                raise RuntimeError(f"{image.name}: the triangulation changed the intrinsics")
        errs = observation_errors(rec, colmap_cams, tmp)
        obs_per_image = {}
        for image_id in rec.reg_image_ids():
            image = rec.image(image_id)
            obs_per_image[image.name[:-4]] = int(image.num_points3D)
        stats = {
            "num_images": len(cameras),
            "num_images_with_points": int(sum(1 for v in obs_per_image.values() if v > 0)),
            "num_verified_pairs": int(n_pairs),
            "num_points3D": int(rec.num_points3D()),
            "num_observations": int(errs.size),
            "mean_px": float(errs.mean()) if errs.size else None,
            "median_px": float(np.median(errs)) if errs.size else None,
            "rms_px": float(np.sqrt((errs ** 2).mean())) if errs.size else None,
            "p90_px": float(np.percentile(errs, 90)) if errs.size else None,
            "colmap_mean_px": float(rec.compute_mean_reprojection_error()),
            "mean_track_length": float(rec.compute_mean_track_length()),
            "max_error_px": float(max_error_px),
            "track_error_px": float(track_error_px),
            # for comparison with COLMAP's default filter (its 4 px threshold)
            "mean_px_within_4px": float(errs[errs <= 4.0].mean()) if (errs <= 4.0).any()
            else None,
            "fraction_within_4px": float((errs <= 4.0).mean()) if errs.size else None,
            "observations_per_image": obs_per_image,
        }
        log.info("reprojection: %d images, %d points, %d observations, mean %.4f px, "
                 "median %.4f px", stats["num_images"], stats["num_points3D"],
                 stats["num_observations"], stats["mean_px"] or float("nan"),
                 stats["median_px"] or float("nan"))
        if model_dir is not None:
            write_points_model(rec, model_dir, images, tmp,
                               max_error_px=track_error_px, min_angle_deg=min_angle_deg)
        return stats
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def filter_for_export(rec, max_error_px: float, min_angle_deg: float) -> tuple[int, int]:
    """Filter ``rec``'s points in place with COLMAP's filter of its own models
    (pycolmap's ``filter_all_points3D``): every observation that reprojects farther than
    ``max_error_px`` or lies behind its camera removed, then every point whose views meet
    at less than ``min_angle_deg`` or that is left with fewer than two observations.
    Table I measures every observation up to ``sfm.reprojection.max_error_px`` (100 px:
    module docstring); a trainer that starts from the points wants COLMAP's 4 px instead,
    or a mismatch becomes a floater metres off the scene. The angle stays Table I's
    (0.1 deg): COLMAP's 1.5 deg drops the points seen within one shot only, about half of
    them (BENCHMARKS.md, "The points model filtered at COLMAP's 4 px"). Returns the points
    and the observations removed."""
    import pycolmap  # noqa: PLC0415

    points, observations = rec.num_points3D(), rec.compute_num_observations()
    pycolmap.ObservationManager(rec).filter_all_points3D(float(max_error_px),
                                                         float(min_angle_deg))
    return (points - rec.num_points3D(), observations - rec.compute_num_observations())


def write_points_model(rec, model_dir: str | Path,
                       images: Mapping[str, str | Path] | None = None,
                       work_dir: str | Path | None = None, *,
                       max_error_px: float = _REPROJ["track_error_px"],
                       min_angle_deg: float = _REPROJ["min_angle_deg"]) -> None:
    """``rec`` (the triangulation of :func:`triangulated_stats`: every view a camera of its
    own, set to the calibration, its pose the calibration's; the 3-D points with their
    tracks), filtered with COLMAP's filter (:func:`filter_for_export`: at ``max_error_px``,
    COLMAP's 4 px, and Table I's ``min_angle_deg``; ``rec`` is changed),
    written as a COLMAP binary model into ``model_dir`` (atomically), each point
    coloured by the mean of its observations in ``images`` (view key -> image file; the
    model's image names are ``<key>.png``). Gaussian-splatting trainers that start from
    COLMAP's points read it with the views as its images folder (README)."""
    from plenocal.io.files import atomic_write_dir  # noqa: PLC0415

    points, observations = filter_for_export(rec, max_error_px, min_angle_deg)
    log.info("points model: %d points and %d observations past %.1f px or %.2f deg left out "
             "(COLMAP's filter), %d points kept", points, observations, max_error_px,
             min_angle_deg, rec.num_points3D())
    if images is not None:
        root = Path(tempfile.mkdtemp(prefix="plenocal_colours_", dir=work_dir))
        try:
            for image_id in rec.reg_image_ids():
                name = rec.image(image_id).name
                key = name[:-4] if name.endswith(".png") else name
                if key not in images:
                    raise ValueError(f"{name}: no image file for the points' colours")
                link = root / name
                link.parent.mkdir(parents=True, exist_ok=True)
                link.symlink_to(Path(images[key]).resolve())
            rec.extract_colors_for_all_images(str(root))
        finally:
            shutil.rmtree(root, ignore_errors=True)
    atomic_write_dir(model_dir, lambda tmp: rec.write_binary(str(tmp)))


def reprojection_stats(cameras: Mapping[str, PinholeCamera], images: Mapping[str, str | Path],
                       *, max_num_features: int = cm.DEFAULT_MAX_FEATURES,
                       seed: int = cm.DEFAULT_SEED, num_threads: int = cm.DEFAULT_THREADS,
                       work_dir: str | Path | None = None, **kwargs) -> dict:
    """:func:`triangulated_stats` on a view database built here from ``images`` (same
    names as ``cameras``): every pair within a shot and the same view across every two
    shots (exhaustive for names without '/'). ``kwargs``: the triangulation options."""
    missing = sorted(set(cameras) - set(images))
    if missing:
        raise ValueError(f"no image for calibrated views {', '.join(missing[:10])}")
    tmp = Path(tempfile.mkdtemp(prefix="plenocal_viewdb_", dir=work_dir))
    try:
        db = tmp / "views.db"
        viewdb.build_view_database({k: images[k] for k in cameras}, db, tmp,
                                   shot_neighbours=None, view_radius=None,
                                   within_shot="grid",
                                   max_num_features=max_num_features, seed=seed,
                                   num_threads=num_threads)
        return triangulated_stats(cameras, db, seed=seed, num_threads=num_threads,
                                  work_dir=tmp, **kwargs)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def reg_a_views(reg_a: RegistrationA, central: str) -> dict[str, PinholeCamera]:
    """Registration A -> ``{"<cam>/<central>": PinholeCamera}`` (SfM units)."""
    return {view_key(cam, central): c for cam, c in reg_a.cameras.items()}


def shot_counts(names) -> dict:
    """Array and hand-held shot counts of ``<cam>/<view>`` names (Table I writes
    "21 + 7")."""
    names = list(names)
    shots = {key_shot(n) for n in names}
    hand = sum(1 for s in shots if is_handheld_shot(s))
    views = len(names)
    in_hand = sum(1 for n in names if is_handheld_shot(key_shot(n)))
    return {"num_shots": len(shots), "num_handheld_shots": hand,
            "num_array_images": views - in_hand, "num_handheld_images": in_hand,
            "num_views": views}


def evaluate(cameras: Mapping[str, PinholeCamera], database: str | Path, **kwargs) -> dict:
    """:func:`triangulated_stats` of the views of the view ``database`` that have a
    camera, with the shot counts; views without a camera are listed
    (``missing_cameras``)."""
    names = viewdb.database_names(database)
    use = {k: v for k, v in cameras.items() if k in set(names)}
    stats = triangulated_stats(use, database, **kwargs)
    stats.update(shot_counts(sorted(use)))
    stats["missing_cameras"] = sorted(set(names) - set(cameras))
    return stats


def evaluate_sets(rig: RigB, database: str | Path, **kwargs) -> dict:
    """Registration B: every shot's N x N set of the view ``database`` on its own, and
    the mean over the sets."""
    by_shot: dict[str, list[str]] = {}
    for name in viewdb.database_names(database):
        by_shot.setdefault(key_shot(name), []).append(name)
    sets = {}
    for cam in sorted(by_shot):
        log.info("registration B: set %s", cam)
        cams = rig.set_cameras(cam)
        sets[cam] = triangulated_stats({k: cams[k] for k in by_shot[cam]}, database,
                                       **kwargs)
        sets[cam].update(shot_counts(by_shot[cam]))
    means = [s["mean_px"] for s in sets.values() if s["mean_px"] is not None]
    medians = [s["median_px"] for s in sets.values() if s["median_px"] is not None]
    return {"sets": sets,
            "mean_px": float(np.mean(means)) if means else None,
            "median_px": float(np.mean(medians)) if medians else None,
            "mean_of": "per-set mean and median, averaged over the sets",
            "num_sets": len(sets),
            "num_images": int(np.median([s["num_images"] for s in sets.values()])) if sets
            else 0,
            "num_observations": int(sum(s["num_observations"] for s in sets.values()))}


def table_i(evals: Mapping[str, dict], baseline: dict, scratch: dict | None = None) -> dict:
    """The rows of Table I (rule reprojection): one calibration's evaluation each
    (``evals``: name -> :func:`evaluate`'s document), the naive baseline's registered
    count from its mapping (``baseline``: rule baseline_sfm's info), and, where SfM from
    scratch ran (``scratch``: rule baseline_scratch's info), its row."""
    doc = {k: dict(v) for k, v in evals.items()}
    if scratch is not None:
        doc["sfm_scratch"] = {"num_images": scratch["num_images"],
                              "num_registered": scratch["registered_largest_model"],
                              "num_models": scratch["num_models"],
                              "focal_px": scratch.get("focal_px")}
    doc["baseline_sfm"]["num_registered"] = baseline["a_sfm_registered"]
    for name, row in doc.items():
        log.info("Table I %-13s images %4s  mean %s px  median %s px", name,
                 row.get("num_images"), row.get("mean_px"), row.get("median_px"))
    return doc


def evaluate_calibration(name: str, path: str | Path, database: str | Path, central: str,
                         **kwargs) -> dict:
    """The Table I row of calibration ``name`` (rule reprojection_calib), read from
    ``path``: registration A's ``reg_a.json`` (its central views, ``central``),
    registration B's ``rig.json`` (every shot's set by its own rig,
    :func:`evaluate_sets`), or any ``cameras.json`` (the complete calibration, the naive
    baseline, the ground truth). ``kwargs``: :func:`evaluate`'s options."""
    log.info("reprojection of %s (%s) on the view database %s", name, path, database)
    if name == "reg_a":
        out = evaluate(reg_a_views(read_reg_a(path), central), database, **kwargs)
    elif name == "reg_b":
        out = evaluate_sets(read_rig(path), database, **kwargs)
    else:
        out = evaluate(read_cameras(path), database, **kwargs)
    out["calibration"] = name
    return out
