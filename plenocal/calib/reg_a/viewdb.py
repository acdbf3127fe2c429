"""The feature database of every subaperture view, shared by the verification stages.

Table I of the paper triangulates the same SIFT matches with each calibration's poses
held fixed, and the naive A+SfM baseline registers the same views by structure from
motion. SIFT of all views and their matching are the same work for every calibration,
so they are done once (rule ``view_matches``) into one COLMAP database: one shared
camera, COLMAP's default focal guess, no calibration used, so that every calibration
is measured on the very same verified matches.

Each use then takes a copy of the part it needs (:func:`subset_database`): the images
of one calibration, each with its own camera set to that calibration's intrinsics
(registration B and the complete calibration shift the principal point per view), or
all of them sharing one camera (the baselines). Descriptors and raw matches are not
copied: triangulation and mapping read keypoints and verified matches only.

SIFT needs no calibration and runs per shot as soon as its views exist
(:func:`extract_view_features`, rule ``view_features``: 28 short jobs that the
scheduler spreads over the cores alongside the conversion and registration A); the
matching, whose pairs follow A's camera centres, merges the shots' features into one
database (:func:`merge_view_features`, as one extraction of all views would lay it
out) and adds the verified matches (:func:`match_views`, rule ``view_matches``).

Which pairs are matched (:func:`view_pairs`): within a shot, each view and the shot's
central view (``within_shot: centre``, the default: N x N - 1 pairs a shot, the tracks
joined through the central view), or the views at most ``view_radius`` apart on the
N x N grid (``within_shot: grid``: 72 pairs of 5 x 5 views at radius 1); across shots,
the same view of each shot and its ``shot_neighbours`` nearest shots (by registration
A's camera centres), with the shortest links that join the groups these may leave apart
(:func:`nearest_shots`). Exhaustive matching of the default dataset's 700 views is
244,650 pairs and the "sets" pairing (every pair within a shot, the same view across
every two shots) 17,850; the grid at radius 1 about 3,000 and the central view's pairs
about 1,600 (default-s21 of bench/bench_accuracy.py: 2,966 and 1,622). Tracks still
chain across the whole array through the overlaps.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import re
import shutil
import sqlite3
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import numpy as np

from plenocal.calib.groups import Groups
from plenocal.calib.reg_a import colmap as cm
from plenocal.camera import PinholeCamera, k_to_colmap

_MATCHING = cm.SFM_DEFAULTS["view_matching"]  # the pairs' defaults: the schema's

log = logging.getLogger(__name__)

_VIEW = re.compile(r"^(\d+)_(\d+)$")


def split_name(name: str) -> tuple[str, str]:
    """``"<cam>/<view>.png"`` (or without the extension) -> (cam, view); a name without
    '/' is a shot of its own with an empty view."""
    if name.endswith(".png"):
        name = name[:-4]
    cam, _, view = name.partition("/")
    return cam, view


def _grid(view: str) -> tuple[int, int] | None:
    m = _VIEW.match(view)
    return (int(m.group(1)), int(m.group(2))) if m else None


def nearest_shots(centres: Mapping[str, np.ndarray], k: int) -> set[tuple[str, str]]:
    """Unordered shot pairs (sorted tuples) linking each shot to its ``k`` nearest
    shots by camera centre, and where these leave the shots in separate groups, the
    shortest pair between two groups, again until one group is left (as Kruskal's
    spanning tree would): on a regular array each shot has up to four neighbours at the
    same step, and two nearest of them split two captures of ten in two, with no match
    to tie one half's place to the other's (rule refine, :mod:`plenocal.calib.refine`).
    Ties are broken by name, so the result is fixed."""
    shots = sorted(centres)
    dist = {(a, b): float(np.linalg.norm(np.asarray(centres[a]) - np.asarray(centres[b])))
            for a, b in itertools.combinations(shots, 2)}
    out: set[tuple[str, str]] = set()
    for a in shots:
        others = sorted((dist[tuple(sorted((a, b)))], b) for b in shots if b != a)
        for _, b in others[:k]:
            out.add(tuple(sorted((a, b))))
    groups = Groups(shots)
    for a, b in out:
        groups.join(a, b)
    for (a, b), _ in sorted(dist.items(), key=lambda kv: (kv[1], kv[0])):
        if groups.join(a, b):
            out.add((a, b))
    return out


def central_views(names: Iterable[str]) -> dict[str, tuple[int, int]]:
    """Each shot's central view on its grid, ``<cam>`` -> (row, col): the middle of the
    rows and columns its ``<row>_<col>`` names span, where that is a whole view the shot
    has. Shots without one (an even grid, a missing view, names off the grid) are left
    out."""
    grids: dict[str, set[tuple[int, int]]] = {}
    for n in names:
        cam, view = split_name(n)
        g = _grid(view)
        if g is not None:
            grids.setdefault(cam, set()).add(g)
    out = {}
    for cam, g in grids.items():
        rows, cols = [r for r, _ in g], [c for _, c in g]
        twice = (min(rows) + max(rows), min(cols) + max(cols))
        centre = (twice[0] // 2, twice[1] // 2)
        if twice[0] % 2 == 0 and twice[1] % 2 == 0 and centre in g:
            out[cam] = centre
    return out


def view_pairs(names: Iterable[str], shot_centres: Mapping[str, np.ndarray] | None = None,
               *, shot_neighbours: int | None = _MATCHING["shot_neighbours"],
                  view_radius: int | None = _MATCHING["view_radius"],
                  within_shot: str = _MATCHING["within_shot"]
               ) -> list[tuple[str, str]]:
    """Image pairs to match among ``<cam>/<view>.png`` names (module docstring).

    ``within_shot`` "centre": each view of a shot with the shot's central view
    (:func:`central_views`; a shot without one is paired as "grid"); "grid": the views
    at most ``view_radius`` apart (None: every pair within a shot). ``shot_neighbours``
    None (or no centres): the same view across every two shots. Views whose names are
    not ``<row>_<col>`` are paired with every view of their shot. Sorted."""
    if within_shot not in ("centre", "grid"):
        raise ValueError(f"config sfm.view_matching.within_shot = {within_shot!r}: "
                         "centre or grid")
    names = sorted(names)
    shots = sorted({split_name(n)[0] for n in names})
    central = central_views(names) if within_shot == "centre" else {}
    linked = None
    if shot_neighbours is not None and shot_centres is not None:
        known = {s: shot_centres[s] for s in shots if s in shot_centres}
        linked = nearest_shots(known, shot_neighbours)
        unknown = [s for s in shots if s not in known]
        linked |= {tuple(sorted((a, b))) for a in unknown for b in shots if a != b}
    out = []
    for a, b in itertools.combinations(names, 2):
        ca, va = split_name(a)
        cb, vb = split_name(b)
        if ca == cb:
            ga, gb = _grid(va), _grid(vb)
            if ga is None or gb is None:
                out.append((a, b))
            elif ca in central:
                if central[ca] in (ga, gb):
                    out.append((a, b))
            elif (view_radius is None
                    or max(abs(ga[0] - gb[0]), abs(ga[1] - gb[1])) <= view_radius):
                out.append((a, b))
        elif va == vb and (linked is None or tuple(sorted((ca, cb))) in linked):
            out.append((a, b))
    return out


def extract_view_features(images: Mapping[str, str | Path], database: str | Path,
                          work_dir: str | Path, *, max_num_features: int = cm.DEFAULT_MAX_FEATURES,
                          seed: int = cm.DEFAULT_SEED, num_threads: int = cm.DEFAULT_THREADS,
                          first_octave: int = cm.DEFAULT_FIRST_OCTAVE,
                          extractor: str = cm.DEFAULT_EXTRACTOR, use_gpu: bool = False) -> dict:
    """SIFT of ``images`` (``"<cam>/<view>"`` -> png) into a new ``database``, one
    shared camera with no prior focal length; ``work_dir`` receives the staged images.
    Needs no calibration, so it runs while registration A is computed (rule
    view_features). Returns counts and the time taken."""
    t0 = time.perf_counter()
    image_dir = Path(work_dir) / "images"
    names = cm.stage_images(images, image_dir)
    sizes = {cm.image_size(image_dir / n) for n in names[:1] + names[-1:]}
    if len(sizes) != 1:
        raise ValueError(f"the views differ in size ({sorted(sizes)}); convert every shot "
                         "with the same settings")
    cm.extract_features(database, image_dir, [(names, None)], model="PINHOLE",
                        max_num_features=max_num_features, num_threads=num_threads,
                        seed=seed, first_octave=first_octave, extractor=extractor,
                        use_gpu=use_gpu)
    import pycolmap  # noqa: PLC0415

    with pycolmap.Database.open(str(database)) as db:
        kp = [db.num_keypoints_for_image(im.image_id) for im in db.read_all_images()]
    seconds = time.perf_counter() - t0
    log.info("view features: %d images, %.0f keypoints per image, %.1f s", len(names),
             np.mean(kp), seconds)
    return {"num_images": len(names), "keypoints_mean": float(np.mean(kp)),
            "keypoints_min": int(min(kp)), "first_octave": first_octave, "sift": extractor,
            "device": cm.sift_device(extractor, use_gpu),
            "features_s": seconds}


def merge_view_features(parts: Iterable[str | Path], database: str | Path) -> dict:
    """Merge SIFT databases of disjoint sets of views (:func:`extract_view_features`
    per shot, rule ``view_features``) into a new ``database`` laid out as one
    extraction of all of them: one shared camera, one rig, a frame per image, image
    ids in sorted name order. The parts are read from private copies (pycolmap writes
    to any database it opens) and stay untouched. Returns the keypoint counts."""
    import pycolmap  # noqa: PLC0415

    database = Path(database)
    if database.exists():
        database.unlink()
    entries = []  # (name, camera, keypoints, descriptors)
    for part in sorted(Path(p) for p in parts):
        copy = database.with_name(f".{database.stem}.part.db")
        shutil.copyfile(part, copy)
        try:
            with pycolmap.Database.open(str(copy)) as db:
                cams = {c.camera_id: c for c in db.read_all_cameras()}
                for im in db.read_all_images():
                    entries.append((im.name, cams[im.camera_id], part,
                                    db.read_keypoints(im.image_id),
                                    db.read_descriptors(im.image_id)))
        finally:
            copy.unlink()
    entries.sort(key=lambda e: e[0])
    names = [e[0] for e in entries]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"views in more than one features database: {', '.join(dup[:10])}")
    if not entries:
        raise ValueError("no features databases to merge")
    first = entries[0][1]
    for name, cam, part, _, _ in entries:
        if (cam.model_name, int(cam.width), int(cam.height), list(cam.params)) != (
                first.model_name, int(first.width), int(first.height), list(first.params)):
            raise ValueError(f"{part}: view {name} is {cam.width}x{cam.height} "
                             f"({cam.model_name} {list(cam.params)}), the others "
                             f"{first.width}x{first.height}; convert every shot with the "
                             "same settings")
    with pycolmap.Database.open(str(database)) as d:
        camera = pycolmap.Camera.create_from_model_name(0, first.model_name, 1.0,
                                                        int(first.width), int(first.height))
        camera.params = list(first.params)
        camera.has_prior_focal_length = first.has_prior_focal_length
        cam_id = d.write_camera(camera)
        rig = pycolmap.Rig()
        rig.add_ref_sensor(pycolmap.sensor_t(pycolmap.SensorType.CAMERA, cam_id))
        rig_id = d.write_rig(rig)
        for image_id, (name, _, _, kp, desc) in enumerate(entries, start=1):
            frame = pycolmap.Frame()
            frame.rig_id = rig_id
            frame.add_data_id(pycolmap.data_t(
                pycolmap.sensor_t(pycolmap.SensorType.CAMERA, cam_id), image_id))
            frame_id = d.write_frame(frame)
            d.write_image(pycolmap.Image(name=name, camera_id=cam_id, image_id=image_id,
                                         frame_id=frame_id), use_image_id=True)
            d.write_keypoints(image_id, kp)
            d.write_descriptors(image_id, desc)
    kp = [e[3].shape[0] for e in entries]
    return {"num_images": len(entries), "keypoints_mean": float(np.mean(kp)),
            "keypoints_min": int(min(kp))}


def match_views(database: str | Path, *,
                shot_centres: Mapping[str, np.ndarray] | None = None,
                shot_neighbours: int | None = _MATCHING["shot_neighbours"],
                view_radius: int | None = _MATCHING["view_radius"],
                within_shot: str = _MATCHING["within_shot"],
                seed: int = cm.DEFAULT_SEED, num_threads: int = cm.DEFAULT_THREADS,
                work_dir: str | Path | None = None, use_gpu: bool = False) -> dict:
    """Match (on the GPU with ``use_gpu``) and verify, in the SIFT ``database`` itself, the pairs of
    :func:`view_pairs`. Returns counts and the time taken."""
    t0 = time.perf_counter()
    names = [f"{n}.png" for n in database_names(database)]
    pairs = view_pairs(names, shot_centres, shot_neighbours=shot_neighbours,
                       view_radius=view_radius, within_shot=within_shot)
    # verified as pairs of two cameras: the shared camera's shared-focal estimator takes
    # 3.5x the time (plenocal.calib.reg_a.colmap._match_per_image)
    n_verified = cm.match(database, pairs, seed=seed, num_threads=num_threads,
                          work_dir=work_dir, use_gpu=use_gpu, per_image_verification=True)
    rewrite_in_key_order(database)
    seconds = time.perf_counter() - t0
    log.info("view matches: %d images, %d pairs (%d verified), %.1f s", len(names),
             len(pairs), n_verified, seconds)
    return {"num_images": len(names), "num_pairs": len(pairs),
            "num_verified_pairs": int(n_verified), "shot_neighbours": shot_neighbours,
            "view_radius": view_radius, "within_shot": within_shot,
            "matching_device": "cuda" if use_gpu else "cpu"}


def rewrite_in_key_order(database: str | Path) -> None:
    """Rewrite the SQLite ``database`` in place with every table's rows in key order
    (SQLite's ``VACUUM INTO`` a fresh file, which COLMAP's WAL mode is then set on again).

    COLMAP's matcher on several threads writes the same rows (each pair's RANSAC is seeded
    on its own) in the order its threads finish them, and the file's pages follow that
    order: the same matches, other bytes, and Snakemake's checksums would see a change
    where there is none. Rewritten, the file is the same bytes with any number of threads
    (BENCHMARKS.md, "The view matching on two threads"). The rewrite goes to a temporary
    file beside it that replaces it only once complete."""
    database = Path(database)
    tmp = database.with_name(f".{database.name}.in_key_order")
    tmp.unlink(missing_ok=True)
    try:
        with contextlib.closing(sqlite3.connect(database)) as con:
            con.execute("VACUUM INTO ?", (str(tmp),))
        with contextlib.closing(sqlite3.connect(tmp)) as con:
            con.execute("PRAGMA journal_mode=WAL")
        tmp.replace(database)
    finally:
        tmp.unlink(missing_ok=True)


def match_view_database(features: str | Path, database: str | Path, **kwargs) -> dict:
    """Copy the SIFT ``features`` database (left untouched) to ``database`` and
    :func:`match_views` there (``kwargs``: its options)."""
    shutil.copyfile(features, database)
    return match_views(database, **kwargs)


def build_view_database(images: Mapping[str, str | Path], database: str | Path,
                        work_dir: str | Path, *,
                        shot_centres: Mapping[str, np.ndarray] | None = None,
                        shot_neighbours: int | None = _MATCHING["shot_neighbours"],
                        view_radius: int | None = _MATCHING["view_radius"],
                        within_shot: str = _MATCHING["within_shot"],
                        max_num_features: int = cm.DEFAULT_MAX_FEATURES,
                        seed: int = cm.DEFAULT_SEED, num_threads: int = cm.DEFAULT_THREADS,
                        first_octave: int = cm.DEFAULT_FIRST_OCTAVE,
                        extractor: str = cm.DEFAULT_EXTRACTOR, use_gpu: bool = False) -> dict:
    """:func:`extract_view_features` and :func:`match_view_database` in one go (the
    workflow runs them as two rules): SIFT of ``images`` and the matching of
    :func:`view_pairs` into a new ``database``; ``work_dir`` receives the staged images
    and the features database. Returns counts and timings."""
    features = Path(work_dir) / "features.db"
    info = extract_view_features(images, features, work_dir,
                                 max_num_features=max_num_features, seed=seed,
                                 num_threads=num_threads, first_octave=first_octave,
                                 extractor=extractor, use_gpu=use_gpu)
    info.update(match_view_database(features, database, shot_centres=shot_centres,
                                    shot_neighbours=shot_neighbours,
                                    view_radius=view_radius,
                                    within_shot=within_shot, seed=seed,
                                    num_threads=num_threads, work_dir=work_dir,
                                    use_gpu=use_gpu))
    features.unlink()
    return info


def database_names(database: str | Path) -> list[str]:
    """``"<cam>/<view>"`` names of the images of a database, sorted. Read through
    SQLite in read-only mode: opening a database with pycolmap writes to it (its
    schema check), which would make Snakemake rerun every job that reads it. And as an
    immutable file: COLMAP's databases are in WAL mode, and a read-only connection to one
    left its -wal and -shm files beside the rule's input (matches/database.db-shm)."""
    uri = f"{Path(database).resolve().as_uri()}?mode=ro&immutable=1"
    with contextlib.closing(sqlite3.connect(uri, uri=True)) as con:
        names = [row[0] for row in con.execute("SELECT name FROM images")]
    return sorted(n[:-4] if n.endswith(".png") else n for n in names)


def _colmap_camera(cam: PinholeCamera | None, width: int, height: int, camera_id: int):
    import pycolmap  # noqa: PLC0415

    c = pycolmap.Camera.create_from_model_name(camera_id, "PINHOLE", 1.0, width, height)
    if cam is None:
        f = 1.2 * max(width, height)
        c.params = [f, f, width / 2.0, height / 2.0]
        c.has_prior_focal_length = False
    else:
        if (int(cam.width), int(cam.height)) != (width, height):
            raise ValueError(f"the calibration says {cam.width}x{cam.height}, the images "
                             f"are {width}x{height}")
        if abs(cam.K[0, 1]) > 1e-9:
            raise ValueError("a skewed K has no COLMAP PINHOLE equivalent")
        K = k_to_colmap(cam.K)
        c.params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
        c.has_prior_focal_length = True
    return c


def subset_database(src: str | Path, dst: str | Path, names: Iterable[str],
                    cameras: Mapping[str, PinholeCamera] | PinholeCamera | None = None,
                    keep_pair: Callable[[str, str], bool] | None = None) -> int:
    """Copy the images ``names`` (``"<cam>/<view>"``) of database ``src`` into a new
    database ``dst``: their keypoints and the verified matches among them (no
    descriptors). ``cameras`` a mapping: one camera per image, set to its intrinsics;
    a single PinholeCamera or None: one camera shared by all (None: COLMAP's default
    focal guess). Image ids are kept. ``keep_pair``: which verified pairs to copy (by the
    two names ``"<cam>/<view>"``; all by default). Returns the number of verified pairs
    copied.
    ``src`` is left untouched (not even its modification time)."""

    want = {f"{n}.png" for n in names}
    dst = Path(dst)
    if dst.exists():
        dst.unlink()
    # pycolmap writes to any database it opens: read a private copy (database_names)
    src_copy = dst.with_name(f".{dst.stem}.source.db")
    shutil.copyfile(src, src_copy)
    try:
        return _copy_views(src_copy, dst, want, cameras, keep_pair)
    finally:
        src_copy.unlink()


def _copy_views(src: Path, dst: Path, want: set[str],
                cameras: Mapping[str, PinholeCamera] | PinholeCamera | None,
                keep_pair: Callable[[str, str], bool] | None = None) -> int:
    import pycolmap  # noqa: PLC0415

    with pycolmap.Database.open(str(src)) as s:
        cams = {c.camera_id: c for c in s.read_all_cameras()}
        images = [im for im in s.read_all_images() if im.name in want]
        missing = sorted(want - {im.name for im in images})
        if missing:
            raise ValueError(f"views not in the view database {src}: "
                             f"{', '.join(m[:-4] for m in missing[:10])}")
        keypoints = {im.image_id: s.read_keypoints(im.image_id) for im in images}
        pair_ids, tvgs = s.read_two_view_geometries()
    ids = {im.image_id for im in images}
    name_of = {im.image_id: im.name[:-4] for im in images}
    per_image = isinstance(cameras, Mapping)
    n_pairs = 0
    with pycolmap.Database.open(str(dst)) as d:
        shared_id = None
        for im in sorted(images, key=lambda i: i.image_id):
            src_cam = cams[im.camera_id]
            w, h = int(src_cam.width), int(src_cam.height)
            if per_image or shared_id is None:
                cam = cameras[im.name[:-4]] if per_image else cameras
                cam_id = d.write_camera(_colmap_camera(cam, w, h, 0))
                rig = pycolmap.Rig()
                rig.add_ref_sensor(pycolmap.sensor_t(pycolmap.SensorType.CAMERA, cam_id))
                rig_id = d.write_rig(rig)
                shared_id = (cam_id, rig_id)
            cam_id, rig_id = shared_id
            frame = pycolmap.Frame()
            frame.rig_id = rig_id
            frame.add_data_id(pycolmap.data_t(
                pycolmap.sensor_t(pycolmap.SensorType.CAMERA, cam_id), im.image_id))
            frame_id = d.write_frame(frame)
            d.write_image(pycolmap.Image(name=im.name, camera_id=cam_id,
                                         image_id=im.image_id, frame_id=frame_id),
                          use_image_id=True)
            d.write_keypoints(im.image_id, keypoints[im.image_id])
        for pid, tvg in zip(pair_ids, tvgs, strict=True):
            a, b = pycolmap.pair_id_to_image_pair(pid)
            if (a in ids and b in ids and tvg.inlier_matches.shape[0] > 0
                    and (keep_pair is None or keep_pair(name_of[a], name_of[b]))):
                d.write_two_view_geometry(a, b, tvg)
                n_pairs += 1
    return n_pairs
