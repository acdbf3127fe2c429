"""Shot and view names: the one place that spells them.

A dataset's shots are the array shots ``x{col:02d}_y{row:02d}`` (column ``col`` grows
to the right, row ``row`` downwards) and the hand-held shots ``hand{k:02d}``. The views
of a shot are ``{r}_{c}`` on its N x N grid (``r`` grows as the viewpoint moves down,
``c`` as it moves right; :mod:`plenocal.viewgeom`). A view of a dataset is keyed
``{shot}/{r}_{c}``: the keys of ``cameras.json``, of the depth maps and of every table
of per-view results.

Everything else parses these names through the functions here, never by slicing or
splitting strings, so that a malformed name fails with the name in the message.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Iterable
from pathlib import PurePath

# ASCII digits only ([0-9], not \d: Python's \d also matches the digits of other scripts,
# "x\u0660\u0660_y\u0660\u0660" would pass), and whole names only (fullmatch: "$" also
# matches before a trailing newline)
SHOT_PATTERN = r"x[0-9]{2}_y[0-9]{2}|hand[0-9]{2}"
VIEW_PATTERN = r"[0-9]+_[0-9]+"
_ARRAY_RE = re.compile(r"x([0-9]{2})_y([0-9]{2})")
_HAND_RE = re.compile(r"hand([0-9]{2})")
_VIEW_RE = re.compile(r"([0-9]+)_([0-9]+)")
_KEY_RE = re.compile(rf"({SHOT_PATTERN})/({VIEW_PATTERN})")


class BadName(ValueError):
    """A shot, view or view key that does not follow the naming scheme."""


def array_shot(col: int, row: int) -> str:
    """The array shot in column ``col``, row ``row``: ``x{col:02d}_y{row:02d}``."""
    return f"x{col:02d}_y{row:02d}"


def handheld_shot(k: int) -> str:
    """The ``k``-th hand-held shot: ``hand{k:02d}``."""
    return f"hand{k:02d}"


def array_shots(cols: int, rows: int) -> list[str]:
    """Every array shot, row-major (row 0 first)."""
    return [array_shot(c, r) for r in range(rows) for c in range(cols)]


def handheld_shots(count: int) -> list[str]:
    return [handheld_shot(k) for k in range(count)]


def is_shot(name: str) -> bool:
    return bool(_ARRAY_RE.fullmatch(name) or _HAND_RE.fullmatch(name))


def is_array_shot(name: str) -> bool:
    return _ARRAY_RE.fullmatch(name) is not None


def is_handheld_shot(name: str) -> bool:
    return _HAND_RE.fullmatch(name) is not None


def array_position(name: str) -> tuple[int, int] | None:
    """(col, row) of an array shot; None for a hand-held shot; an error otherwise."""
    m = _ARRAY_RE.fullmatch(name)
    if m:
        return int(m.group(1)), int(m.group(2))
    if _HAND_RE.fullmatch(name):
        return None
    raise BadName(f"{name!r} is not a shot name (x<col>_y<row> or hand<k>, two digits)")


def view_name(r: int, c: int) -> str:
    return f"{r}_{c}"


#: a recording's per-frame folder of views (``plenocal convert --format png`` of a video)
FRAME_FOLDER_PATTERN = r"frame_[0-9]{5}"


def frame_folder(k: int) -> str:
    """The folder of frame ``k``'s views in a recording's PNG output: ``frame_{k:05d}``."""
    return f"frame_{k:05d}"


def parse_view(name: str) -> tuple[int, int]:
    """(r, c) of a view name ``{r}_{c}``."""
    m = _VIEW_RE.fullmatch(name)
    if not m:
        raise BadName(f"{name!r} is not a view name (<row>_<col>)")
    return int(m.group(1)), int(m.group(2))


def view_names(n: int) -> list[str]:
    """The N x N views of a shot, row-major (``n`` a whole number: config ``views``)."""
    try:
        n = operator.index(n)
    except TypeError:
        raise BadName(f"the number of views per side must be a whole number (config "
                      f"datasets.<name>.views), not {n!r}") from None
    return [view_name(r, c) for r in range(n) for c in range(n)]


def central_view(n: int) -> str:
    h = (n - 1) // 2
    return view_name(h, h)


def middle_view(views: Iterable[str]) -> str:
    """The view nearest the centre of the rows and columns that ``views`` span: a shot's
    central view when they are its N x N set, the one view of a hand-held shot. By number,
    not as text, where ``10_10`` sorts before ``2_2``."""
    rc = {v: parse_view(v) for v in views}
    if not rc:
        raise BadName("no view names to take the central view of")
    rows, cols = [r for r, _ in rc.values()], [c for _, c in rc.values()]
    rm, cm = (min(rows) + max(rows)) / 2, (min(cols) + max(cols)) / 2
    return min(sorted(rc, key=rc.__getitem__),
               key=lambda v: abs(rc[v][0] - rm) + abs(rc[v][1] - cm))


def view_key(shot: str, view: str) -> str:
    """The dataset-wide key of a view: ``{shot}/{view}``."""
    return f"{shot}/{view}"


def flat_key(key: str) -> str:
    """``<shot>/<view>`` (and a file name made of it) -> ``<shot>_<view>``: one name per
    view where a folder may not hold the shot (MPEG-I camera names, the Gaussian-splatting
    dataset's images)."""
    return key.replace("/", "_")


def file_key(path: str | PurePath) -> str:
    """The key of a view's file ``.../{shot}/{view}.<ext>`` (a view image, depth map or
    render): :func:`view_key` of its folder's name and its stem."""
    path = PurePath(path)
    return view_key(path.parent.name, path.stem)


def split_key(key: str) -> tuple[str, str]:
    """(shot, view) of a view key ``{shot}/{r}_{c}``."""
    m = _KEY_RE.fullmatch(key)
    if not m:
        raise BadName(f"{key!r} is not a view key (<shot>/<row>_<col>, shot "
                         "x<col>_y<row> or hand<k>)")
    return m.group(1), m.group(2)


def key_shot(key: str) -> str:
    return split_key(key)[0]


def key_view(key: str) -> str:
    return split_key(key)[1]


def is_key(key: str) -> bool:
    return _KEY_RE.fullmatch(key) is not None
