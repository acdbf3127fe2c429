"""``refine/tracks/<source>/``: one track set of the joint refinement (rule
``refine_tracks`` -> rule ``refine``; :mod:`plenocal.calib.refine`).

A track set is the refinement's points with their observations: the central views'
matches carried into every view (``central``) or every view's own matches (``views``),
triangulated with the Eq. 6 cameras and their observations aligned by their patches
(:class:`TrackSet`; :mod:`plenocal.calib.central_tracks` and :mod:`plenocal.calib.refine`
make them). Each source is made by a job of its own,
so that on two cores the two sets are made side by side, and the adjustments start from
them (BENCHMARKS.md, "The refine job's track sets as jobs of their own").

The folder holds ``tracks.json`` (format name and version, the images by id in the set's
order, the points' count, the alignment's statistics) and six ``.npy`` arrays: every
image's keypoints one after another (``keypoints.npy``, float64 (n, 2), COLMAP's
convention; ``keypoint_counts.npy``), and the points in the set's order (``point_ids.npy``,
``xyz.npy`` float64 (p, 3), ``track_lengths.npy``, ``elements.npy`` int64 (e, 2): each
track's (image id, keypoint index) pairs, one track after another). Read back, the set
holds the values written, to the bit and in their order (keypoints as float64): the
adjustments see the same data as when one job made the sets and adjusted them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.versioned import decode
from plenocal.io.files import atomic_write_dir, dumps_json, read_npy, write_npy

FORMAT = "plenocal.tracks"
VERSION = 1
SOURCES = ("central", "views")
#: ``refine.tracks`` -> the track sets it adjusts, in the order they are joined: the
#: central views' matches carried into every view, every view's own matches, or both
#: (rule refine's inputs, :func:`plenocal.calib.track_sets.track_sources`)
SOURCES_OF = {"central": ("central",), "views": ("views",), "both": ("central", "views")}
_ARRAYS = ("keypoints", "keypoint_counts", "point_ids", "xyz", "track_lengths", "elements")
_REMEDY = "rerun rule refine_tracks"


@dataclass
class TrackSet:
    """Tracks over the views: ``names`` image id -> ``"<shot>/<view>.png"``; ``keypoints``
    image name -> (m, 2) COLMAP's convention; ``points`` point id -> (X (3,), its track's
    (image id, keypoint index) pairs); ``triangulated`` the points before any was left
    out."""

    names: dict[int, str]
    keypoints: dict[str, np.ndarray]
    points: dict[int, tuple[np.ndarray, list[tuple[int, int]]]]
    triangulated: int


@dataclass(frozen=True)
class StoredTracks:
    """One track set as rule ``refine_tracks`` wrote it: the set, its source (one of
    :data:`SOURCES`) and the alignment's statistics (refine.json's ``alignment``)."""

    source: str
    tracks: TrackSet
    alignment: dict


def write_tracks(folder: str | Path, source: str, tracks: TrackSet,
                 alignment: Mapping) -> None:
    """Write ``tracks`` (from ``source``) and the alignment's statistics to ``folder``,
    atomically (a killed job leaves no half-written folder)."""
    if source not in SOURCES:
        raise ValueError(f"track set source {source!r}: use one of {', '.join(SOURCES)}")
    images = [[int(i), str(n)] for i, n in tracks.names.items()]
    kp_names = list(tracks.keypoints)
    kps = [np.asarray(tracks.keypoints[n], np.float64).reshape(-1, 2) for n in kp_names]
    pids = list(tracks.points)
    lengths = [len(tracks.points[p][1]) for p in pids]
    elements = [el for p in pids for el in tracks.points[p][1]]
    arrays = {
        "keypoints": np.concatenate(kps) if kps else np.zeros((0, 2)),
        "keypoint_counts": np.array([len(k) for k in kps], np.int64),
        "point_ids": np.array(pids, np.int64),
        "xyz": (np.stack([np.asarray(tracks.points[p][0], np.float64) for p in pids])
                if pids else np.zeros((0, 3))),
        "track_lengths": np.array(lengths, np.int64),
        "elements": np.array(elements, np.int64).reshape(-1, 2),
    }
    doc = {"format": FORMAT, "version": VERSION, "source": source, "images": images,
           "keypoint_images": kp_names, "points": len(pids), "observations": len(elements),
           "triangulated": int(tracks.triangulated), "alignment": dict(alignment)}

    def write(tmp: Path) -> None:
        for key, array in arrays.items():
            write_npy(tmp / f"{key}.npy", array)
        (tmp / "tracks.json").write_text(dumps_json(doc))

    atomic_write_dir(folder, write)


def track_source(folder: str | Path) -> str:
    """The source of the track set in ``folder`` (``tracks.json`` alone: this version
    only)."""
    return decode(Path(folder) / "tracks.json", FORMAT, VERSION, "track set", _REMEDY,
                  lambda doc: str(doc["source"]))


def read_tracks(folder: str | Path) -> StoredTracks:
    """The track set in ``folder`` (this version only), as :func:`write_tracks` wrote it."""
    folder = Path(folder)

    def build(doc: dict) -> StoredTracks:
        missing = [k for k in _ARRAYS if not (folder / f"{k}.npy").is_file()]
        if missing:
            raise ValueError(f"{folder}: track set without {', '.join(missing)}.npy; the "
                             f"folder is damaged: {_REMEDY}")
        a = {k: read_npy(folder / f"{k}.npy") for k in _ARRAYS}
        kp_names = list(doc["keypoint_images"])
        counts = a["keypoint_counts"]
        lengths = a["track_lengths"]
        if (len(counts) != len(kp_names) or int(counts.sum()) != len(a["keypoints"])
                or len(lengths) != len(a["point_ids"])
                or len(lengths) != int(doc["points"])
                or int(lengths.sum()) != len(a["elements"])):
            raise ValueError(f"{folder}: the track set's arrays do not agree with "
                             f"tracks.json; the folder is damaged: {_REMEDY}")
        kp_parts = np.split(a["keypoints"], np.cumsum(counts)[:-1]) if len(counts) else []
        keypoints = dict(zip(kp_names, kp_parts, strict=True))
        el_parts = np.split(a["elements"], np.cumsum(lengths)[:-1]) if len(lengths) else []
        points = {int(p): (xyz, [tuple(e) for e in els.tolist()])
                  for p, xyz, els in zip(a["point_ids"].tolist(), a["xyz"], el_parts,
                                         strict=True)}
        names = {int(i): str(n) for i, n in doc["images"]}
        return StoredTracks(str(doc["source"]),
                            TrackSet(names, keypoints, points, int(doc["triangulated"])),
                            dict(doc["alignment"]))

    return decode(folder / "tracks.json", FORMAT, VERSION, "track set", _REMEDY, build)
