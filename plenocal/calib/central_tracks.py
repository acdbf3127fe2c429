"""The joint refinement's tracks from the central views' matches, carried into every other
view of each shot by their patches (beyond the paper; config ``refine.tracks: central``,
:mod:`plenocal.calib.refine`).

Why: with ``refine.tracks: views`` the refinement's points are the verified matches of
every view (rule ``view_matches``: SIFT of all N x N views of every shot, then their
matching), which the calibration must wait for (BENCHMARKS.md, "The calibration alone").
The observations are then moved by their patches anyway (``refine.align``,
:mod:`plenocal.calib.track_alignment`): SIFT's keypoint in a view other than the central
one only says where to start. The central views of every pair of shots are matched as
registration A matches them (rule ``match_central``, ``matches/central.db``: SIFT at
``refine.central_contrast``, lower than A's, for about twice the keypoints; the database
has registration A's form, images named ``<shot>.png``), so:

1. the central views' verified matches are triangulated with the Eq. 6 cameras held fixed
   (as rule ``view_matches``' are);
2. each point is projected into the other views of each shot whose central view sees it,
   every ``refine.carry_every``-th of them (:func:`extend_to_views`, :func:`strided`): the
   Eq. 6 cameras place it within a few tenths of a pixel
   (moving it by the residual the central view's SIFT keypoint leaves was tried: that
   residual is SIFT's own noise, not shared by the other views, and a third more
   projections failed their alignment on a small-geometry capture);
3. every observation is aligned by its patch to its track's reference observation, which is
   one of the central views' SIFT keypoints (:func:`aligned_track_set`); a projected
   observation whose alignment fails (it left the image, moved more than
   ``refine.align.max_shift_px`` or matched worse than ``min_zncc``: an occlusion, a
   reflection) is dropped, a central view's SIFT keypoint stays as it is, as in the
   views' path.

The result is a :class:`TrackSet`, which :func:`plenocal.calib.rig_model.rig_reconstruction_of`
turns into the rig's reconstruction.

Conventions: keypoints in COLMAP's (pixel centres at +0.5); cameras internal (OpenCV axes,
camera-to-world, pixel centres at integers), as :mod:`plenocal.camera` holds them.
"""

from __future__ import annotations

import logging
import shutil
import sqlite3
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from plenocal.artifacts.tracks import TrackSet
from plenocal.calib import track_alignment as ta
from plenocal.calib.view_greys import grey_of
from plenocal.camera import PinholeCamera, invert_pose, k_to_colmap
from plenocal.names import split_key

if TYPE_CHECKING:
    from plenocal.calib.refine import RefineSettings

log = logging.getLogger(__name__)


def joined(a: TrackSet, b: TrackSet) -> TrackSet:
    """The tracks of ``a`` and ``b`` in one set (``refine.tracks: both``): the images
    matched by name (``a``'s ids kept, ``b``'s other images numbered after ``a``'s
    largest), each image's keypoints ``a``'s then ``b``'s (``b``'s indices moved past
    ``a``'s), ``a``'s points then ``b``'s (ids moved past ``a``'s largest). A point of ``b``
    stays a point of its own even where ``a`` has one at the same place: the two sets come
    from different matches and neither knows the other's points. ``triangulated`` the sum."""
    id_of = {name: i for i, name in a.names.items()}
    if len(id_of) != len(a.names):
        raise ValueError("tracks: two images of one set share a name")
    names = dict(a.names)
    next_id = max(names, default=0) + 1
    b_to_new = {}
    for i in sorted(b.names):
        name = b.names[i]
        if name not in id_of:
            id_of[name] = next_id
            names[next_id] = name
            next_id += 1
        b_to_new[i] = id_of[name]
    empty = np.zeros((0, 2))
    offset = {}
    keypoints = {n: np.asarray(k, float).reshape(-1, 2) for n, k in a.keypoints.items()}
    for name in sorted(b.keypoints):
        own = keypoints.get(name, empty)
        offset[name] = len(own)
        keypoints[name] = np.concatenate([own, np.asarray(b.keypoints[name], float)
                                          .reshape(-1, 2)])
    points = dict(a.points)
    base = max(points, default=0) + 1
    for k, pid in enumerate(sorted(b.points)):
        X, elements = b.points[pid]
        points[base + k] = (X, [(b_to_new[i], offset[b.names[i]] + j) for i, j in elements])
    return TrackSet(names, keypoints, points, a.triangulated + b.triangulated)


def rename_central_images(src: str | Path, dst: str | Path, central: str) -> int:
    """Copy a database of the central views in registration A's form ``src`` (rule
    ``match_central``'s, or registration A's own) to ``dst`` with each image
    ``<shot>.png`` renamed ``<shot>/<central>.png``, the name of the same view in the view
    sets. Returns the number of images. ``src`` is left untouched."""
    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: the central views' database is missing (rule "
                                "match_central writes it): rerun the workflow")
    shutil.copyfile(src, dst)
    # closed, not only committed: a database in WAL mode keeps the change in its -wal file
    # until the last connection closes, and the copy is read as a file of its own
    db = sqlite3.connect(dst)
    try:
        names = [n for (n,) in db.execute("SELECT name FROM images")]
        odd = [n for n in names if "/" in n or not n.endswith(".png")]
        if odd:
            raise ValueError(f"{src}: image {odd[0]!r} is not a shot's central view "
                             "(<shot>.png): not a database of the central views")
        db.execute("UPDATE images SET name = substr(name, 1, length(name) - 4) || ? ",
                   (f"/{central}.png",))
        db.commit()
    finally:
        db.close()
    return len(names)


def _project_colmap(cam: PinholeCamera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (n, 2, COLMAP's convention) of the points ``X`` (n, 3) in ``cam``, and their
    depths (n,)."""
    T = invert_pose(cam.cam_to_world)
    Xc = X @ T[:3, :3].T + T[:3, 3]
    p = Xc @ k_to_colmap(cam.K).T
    z = Xc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return p[:, :2] / p[:, 2:3], z


def extend_to_views(names: Mapping[int, str], keypoints: Mapping[str, np.ndarray],
                    points: Mapping[int, tuple[np.ndarray, list[tuple[int, int]]]],
                    cameras: Mapping[str, PinholeCamera], margin_px: float,
                    stride: int = 1) -> tuple[TrackSet, dict[str, int]]:
    """The tracks of the central views (``names``: their image ids -> ``<shot>/<central>
    .png``, ``keypoints`` their SIFT keypoints by name, ``points`` the triangulated points
    on them) carried into every view of ``cameras`` (``"<shot>/<view>"`` -> camera) of the
    shots whose central view observes each point: the point projected by the view's camera,
    kept where it falls at least ``margin_px`` inside the image and in front of it, and
    only into every ``stride``-th of the shot's other views (``refine.carry_every``): the
    point in row r of the sorted point ids goes into the views whose place j among the
    shot's other views (sorted keys) has ``(j + r) % stride == 0``, so that each point still
    spans the set and each view keeps its share of the points (:func:`strided`).
    Returns the track set over every view (image ids 1.. in the order of the sorted view
    keys; a view's projected keypoints after its own SIFT keypoints where it has any) and,
    by image name, how many SIFT keypoints lead each image's list (the rest are
    projections)."""
    keys = sorted(cameras)
    new_id = {k: i + 1 for i, k in enumerate(keys)}
    by_shot: dict[str, list[str]] = {}
    for k in keys:
        by_shot.setdefault(split_key(k)[0], []).append(k)
    old_to_new = {}
    for i, n in names.items():
        key = n[:-4]
        if key not in new_id:
            raise ValueError(f"central view {n}: no such view in the calibration")
        old_to_new[i] = new_id[key]
    lists: dict[int, list[np.ndarray]] = {i: [] for i in new_id.values()}
    counts = {i: 0 for i in new_id.values()}
    for i_old, i_new in old_to_new.items():
        kp = np.asarray(keypoints[names[i_old]], float).reshape(-1, 2)
        lists[i_new].append(kp)
        counts[i_new] = len(kp)
    lead = dict(counts)
    pids = sorted(points)
    X_all = np.array([np.asarray(points[p][0], float) for p in pids]).reshape(-1, 3)
    # every observation as (point row, image id, keypoint index): the central views' own
    # first, then each carried one, grouped by point at the end
    own = [(r, old_to_new[i], j) for r, p in enumerate(pids) for i, j in points[p][1]]
    observed = [np.array(own, int).reshape(-1, 3)]
    seen: dict[str, list[int]] = {}  # central view -> the rows of the points it sees
    for r, p in enumerate(pids):
        for key in sorted({names[i][:-4] for i, _ in points[p][1]}):
            seen.setdefault(key, []).append(r)
    for central_key in sorted(seen):
        seen_rows = np.array(seen[central_key])
        others = [k for k in by_shot[split_key(central_key)[0]] if k != central_key]
        for j, k in enumerate(others):
            rows = seen_rows[strided(seen_rows, j, stride)]
            cam = cameras[k]
            uv, z = _project_colmap(cam, X_all[rows])
            ok = ((z > 0) & (uv[:, 0] >= margin_px) & (uv[:, 0] <= cam.width - margin_px)
                  & (uv[:, 1] >= margin_px) & (uv[:, 1] <= cam.height - margin_px))
            i = new_id[k]
            lists[i].append(uv[ok])
            n = int(ok.sum())
            observed.append(np.stack([rows[ok], np.full(n, i), counts[i] + np.arange(n)], 1))
            counts[i] += n
    obs = np.concatenate(observed)
    obs = obs[np.lexsort((obs[:, 2], obs[:, 1], obs[:, 0]))]
    ends = np.searchsorted(obs[:, 0], np.arange(len(pids)), side="right").tolist()
    pairs = list(zip(obs[:, 1].tolist(), obs[:, 2].tolist(), strict=True))
    out_points = {p: (X_all[r], pairs[ends[r - 1] if r else 0:ends[r]])
                  for r, p in enumerate(pids)}
    kps = {f"{k}.png": (np.concatenate(lists[new_id[k]]) if lists[new_id[k]]
                        else np.zeros((0, 2))) for k in keys}
    ts = TrackSet({i: f"{k}.png" for k, i in new_id.items()}, kps, out_points, len(points))
    return ts, {f"{k}.png": lead[new_id[k]] for k in keys}


def strided(rows: np.ndarray, j: int, stride: int) -> np.ndarray:
    """Which of the point rows ``rows`` (n,) go into a shot's ``j``-th non-central view
    with ``refine.carry_every`` ``stride`` (:func:`extend_to_views`): a boolean mask (n,),
    true where ``(j + row) % stride == 0``; all true for a stride of 1."""
    if stride < 1:
        raise ValueError(f"config refine.carry_every = {stride}: at least 1")
    return (np.asarray(rows, int) + j) % stride == 0


def aligned_track_set(ts: TrackSet, lead: Mapping[str, int],
                      cameras: Mapping[str, PinholeCamera],
                      load: Callable[[str], np.ndarray], settings: ta.AlignSettings,
                      num_threads: int, min_track: int = 3) -> tuple[TrackSet, dict]:
    """``ts`` (:func:`extend_to_views`) with every observation aligned by its patch to its
    track's reference, which is the SIFT keypoint (one of the first ``lead[name]`` of its
    image) whose camera centre is nearest the mean of the track's
    (:func:`plenocal.calib.track_alignment.track_observations`); projected observations
    whose alignment fails dropped, SIFT's kept as they are; points left with fewer than
    ``min_track`` observations dropped. ``load``: view key -> its grey levels. Returns the
    new set and the alignment's statistics (``dropped``: projected observations left
    out)."""
    cams = {}
    for i, n in ts.names.items():
        cam = cameras[n[:-4]]
        T = invert_pose(cam.cam_to_world)
        cams[i] = (k_to_colmap(cam.K), T[:3, :3], T[:3, 3])
    by_id = {i: ts.keypoints[n] for i, n in ts.names.items()}
    lead_of = {i: lead[n] for i, n in ts.names.items()}
    lead_by_id = np.zeros(max(ts.names) + 1, int)
    lead_by_id[list(lead_of)] = list(lead_of.values())
    obs, rows = ta.track_observations(ts.points, cams, by_id,
                                      may_reference=lambda i, j: j < lead_by_id[i])
    uv, aligned, stats = ta.align_observations(obs, lambda i: load(ts.names[i][:-4]),
                                               settings, num_threads)
    rows = np.asarray(rows, int).reshape(-1, 2)
    projected = rows[:, 1] >= lead_by_id[rows[:, 0]]
    drop = projected & ~aligned
    keypoints = {n: kp.copy() for n, kp in ts.keypoints.items()}
    for i, sel in ta.rows_of(rows[:, 0]).items():
        keypoints[ts.names[i]][rows[sel, 1]] = uv[sel]
    dropped = {(int(i), int(j)) for i, j in rows[drop]}
    points = {}
    for pid in sorted(ts.points):
        X, track = ts.points[pid]
        kept = [el for el in track if el not in dropped]
        if len(kept) >= min_track:
            points[pid] = (X, kept)
    stats = {**stats, "projected": int(projected.sum()), "dropped": int(drop.sum()),
             "images": len(ts.names)}
    return TrackSet(dict(ts.names), keypoints, points, ts.triangulated), stats


def central_track_set(database: str | Path, eq6: Mapping[str, PinholeCamera],
                      central: str, images: Mapping[str, str | Path],
                      settings: RefineSettings, work_dir: Path,
                      align_threads: int | None = None
                      ) -> tuple[TrackSet, dict]:
    """Steps 1-3 of the module docstring: the central views' database ``database``
    (their verified matches, registration A's form), the Eq. 6 cameras of every view
    ``eq6``, the rig's central view's name ``central``, the views' image files ``images``
    (view key -> file), ``settings`` the refinement's
    (:class:`plenocal.calib.refine.RefineSettings`: the triangulation's thresholds,
    ``align`` and the threads), ``work_dir`` COLMAP's scratch folder; ``align_threads``
    the alignment's threads (``settings.num_threads`` where None; the same result on any
    number). Returns the aligned track set and statistics."""
    import cv2  # noqa: F401, PLC0415  (before pycolmap: DESIGN.md, "Known traps")

    from plenocal.calib.reg_a import colmap as cm  # noqa: PLC0415
    from plenocal.calib.reg_a import viewdb  # noqa: PLC0415
    from plenocal.verify import reprojection as rp  # noqa: PLC0415

    t0 = time.perf_counter()
    renamed = work_dir / "reg_a.db"
    rename_central_images(database, renamed, central)
    shots = sorted({split_key(k)[0] for k in eq6})
    keys = [f"{s}/{central}" for s in shots]
    db = work_dir / "central.db"
    viewdb.subset_database(renamed, db, keys, {k: eq6[k] for k in keys})
    colmap_cams = {f"{k}.png": eq6[k] for k in keys}
    rec = cm.known_pose_reconstruction(db, colmap_cams, update_intrinsics=False)
    opts = rp.triangulation_options(settings.max_error_px, settings.min_angle_deg,
                                    settings.seed, settings.num_threads)
    rp.triangulate(rec, db, opts, settings.seed, colmap_cams, work_dir)
    names = {i: rec.image(i).name for i in rec.images}
    keypoints = rp.read_keypoints(rec, work_dir)
    points = {pid: (np.asarray(rec.point3D(pid).xyz, float),
                    [(e.image_id, e.point2D_idx) for e in rec.point3D(pid).track.elements])
              for pid in rec.point3D_ids()}
    t_tri = time.perf_counter() - t0
    margin = float(settings.align.radius_px) + 2.0
    ts, lead = extend_to_views(names, keypoints, points, eq6, margin, settings.carry_every)
    missing = sorted(set(eq6) - set(images))
    if missing:
        raise ValueError(f"refine.tracks central: no image file for {len(missing)} views "
                         f"({', '.join(missing[:5])}): rerun the conversion")

    def load(key: str) -> np.ndarray:
        return grey_of(images, key)

    t1 = time.perf_counter()
    aligned, stats = aligned_track_set(
        ts, lead, eq6, load, settings.align,
        settings.num_threads if align_threads is None else align_threads)
    log.info("tracks of the central views: %d points triangulated on %d central views "
             "(%.1f s), carried into the other views: %d observations projected, %d "
             "dropped where the alignment failed; %d of %d observations aligned (median "
             "shift %s px, %.1f s); %d points of three or more observations",
             len(points), len(keys), t_tri, stats["projected"], stats["dropped"],
             stats["aligned"], stats["observations"],
             "-" if stats["shift_median_px"] is None else f"{stats['shift_median_px']:.3f}",
             time.perf_counter() - t1, len(aligned.points))
    return aligned, stats
