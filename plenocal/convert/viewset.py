"""``views.json``: the N x N subaperture views of one shot, named as one unit.

Rule ``convert_views`` writes it beside the views, once every view of the shot is on
disk (the central one from rule ``convert``, the others from itself). It lists each view
with the SHA-256 of its PNG, so its bytes change exactly when a view's bytes change.

The rules that read whole view sets (SIFT of every view, registration B's depth maps,
the depth maps and view synthesis of the verification, the MPEG exports) take this file
as their input instead of the N x N PNGs: Snakemake looks every input up among all the
rules' outputs and checks it again for each consumer, and the views were 4,188 of the
4,891 look-ups of the default run's DAG - most of a no-op rerun (issue 15). A consumer
still reruns when a view changes (the list's checksum changes). The views on disk are
not outputs in the DAG at all (``rules/common.smk`` ``missing_views``); a deleted view is
declared and asked for again, so rule ``convert_views`` brings it back.

The document: ``{"format": "plenocal.view_set", "version": 1, "shot": <shot>,
"views": {<view name>: <sha256 hex>, ...}}``, keys sorted, written atomically.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from plenocal.artifacts.versioned import complete, read_versioned
from plenocal.io.files import file_sha256, write_json
from plenocal.names import VIEW_PATTERN

FORMAT = "plenocal.view_set"
VERSION = 1
FILE_NAME = "views.json"
_NAME = "view set"
_REMEDY = ("convert the shot again (snakemake --forcerun on its rule convert_views_<k>, or "
           "delete the file)")


def view_set_path(shot_dir: str | Path) -> Path:
    """``<shot_dir>/views.json``."""
    return Path(shot_dir) / FILE_NAME


def write_view_set(shot_dir: str | Path, names: Sequence[str]) -> Path:
    """List the views ``<shot_dir>/<name>.png`` (every one must exist) in
    ``<shot_dir>/views.json``; returns its path."""
    shot_dir = Path(shot_dir)
    missing = [n for n in names if not (shot_dir / f"{n}.png").is_file()]
    if missing:
        raise FileNotFoundError(f"{shot_dir}: views {', '.join(missing)} not found; the "
                                f"view set lists only complete shots: {_REMEDY}")
    doc = {"format": FORMAT, "version": VERSION, "shot": shot_dir.name,
           "views": {n: file_sha256(shot_dir / f"{n}.png") for n in names}}
    path = view_set_path(shot_dir)
    write_json(path, doc)
    return path


#: a view's PNG in a shot's folder (plenocal.names.view_name)
_VIEW_PNG = re.compile(rf"(?:{VIEW_PATTERN})\.png")


def remove_stale_views(shot_dir: str | Path, names: Sequence[str]) -> list[Path]:
    """Remove the view PNGs in ``shot_dir`` that are not among ``names`` (the shot's whole
    view set), and return them: an earlier run's views of another ``views`` setting
    (after 5 x 5 views, a 3 x 3 run left 0_3.png ... 4_4.png, sixteen views, beside its
    own, and the folder a user takes to COLMAP or NeRF mixed two view sets; Snakemake
    removes only the outputs it reruns). Nothing reads them: every consumer reads
    views.json."""
    keep = {f"{n}.png" for n in names}
    stale = sorted(p for p in Path(shot_dir).iterdir()
                   if _VIEW_PNG.fullmatch(p.name) and p.name not in keep)
    for p in stale:
        p.unlink()
    return stale


def read_view_set(path: str | Path) -> dict[str, Path]:
    """The views a ``views.json`` lists: view name -> PNG path (beside the file), sorted
    by name. An error names the file and the remedy when it is not a view set, or when a
    view it lists is no longer on disk."""
    path = Path(path)
    doc = read_versioned(path, FORMAT, VERSION, _NAME, _REMEDY)
    with complete(path, _NAME, VERSION, _REMEDY):
        names = list(doc["views"])
    out = {n: path.parent / f"{n}.png" for n in names}
    gone = [str(p) for p in out.values() if not p.is_file()]
    if gone:
        raise FileNotFoundError(f"{path}: lists views that are not on disk ({', '.join(gone)}); "
                                f"{_REMEDY}")
    return out


def view_set_files(paths: Sequence[str | Path]) -> dict[str, Path]:
    """The views of several shots' view sets, keyed ``<shot>/<view>`` (the keys of
    :mod:`plenocal.names`)."""
    out: dict[str, Path] = {}
    for p in paths:
        shot = Path(p).parent.name
        for name, file in read_view_set(p).items():
            out[f"{shot}/{name}"] = file
    return out
