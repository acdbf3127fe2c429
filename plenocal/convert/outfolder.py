"""The command line's output folder holds one conversion (``plenocal convert -o DIR``).

A conversion replaces the files of the same names in its folder. Without a check, an
earlier conversion's files of other names stayed beside the new ones: a 7 x 7 run's views
0_3.png ... 6_6.png (forty views) beside a 3 x 3 run's 0_0.png ... 2_2.png (another view
set, 0_0 then a corner at another offset), or a recording's frames beside a still's views,
and the folder handed to COLMAP, TMIV or NeRF mixed two conversions.
:func:`check_output_folder` stops such a run before its work, naming the files; nothing is
removed that the user did not ask to replace (a rerun's per-view videos replace their
views' videos of another size, :func:`stale_view_videos`). What is allowed to stay: files
the conversion does not write (the user's own), and a recording's frame folders of the
same view set (a recording converted in chunks of ``--frames`` into one folder).
"""
from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

from plenocal.convert.errors import ConvertError
from plenocal.names import FRAME_FOLDER_PATTERN, VIEW_PATTERN, frame_folder, view_names

#: the names ``plenocal convert`` writes in its output folder: a still image's views,
#: patch sizes and disparity.json; a recording's view videos (plenocal.io.yuv.mpeg_name),
#: frame folders, set-up and video.json
CONVERSION_NAME = re.compile(
    rf"(?P<view>{VIEW_PATTERN})\.png|v_(?P<video>{VIEW_PATTERN})_\S+\.yuv|{FRAME_FOLDER_PATTERN}"
    r"|patch_size\.(?:npy|png)|disparity\.json|video\.json|convert_setup\.json")

#: a still image's files besides its views (plenocal.cli)
STILL_FILES = ("patch_size.npy", "patch_size.png", "disparity.json")
#: a recording's files besides its views and frames (plenocal.convert.video)
RECORDING_FILES = ("convert_setup.json", "video.json")


#: what a run does with a name in its folder (a claim): writes it again, lets it stay
#: beside its own (another chunk's frame folder, looked at), or neither (a stale file)
REPLACED, KEPT = "replaced", "kept"


def still_claims(n_views: int) -> Callable[[str], str | None]:
    """The names a still image's conversion of ``n_views`` x ``n_views`` views writes."""
    names = {f"{v}.png" for v in view_names(n_views)} | set(STILL_FILES)
    return lambda name: REPLACED if name in names else None


def recording_claims(n_views: int, frames: range, out_format: str
                     ) -> Callable[[str], str | None]:
    """The names a recording's conversion writes again: ``yuv``, the view videos of its
    view set (of any size: :func:`stale_view_videos` removes the other sizes' at the end);
    ``png``, the frame folders ``frames``. And those it keeps beside its own: with ``png``,
    the folders of other frames (a recording converted in chunks of ``--frames``; of the
    same view set, which :func:`check_output_folder` looks at)."""
    views = set(view_names(n_views))
    own = set(RECORDING_FILES)
    if out_format == "png":
        own |= {frame_folder(k) for k in frames}

    def claims(name: str) -> str | None:
        if name in own:
            return REPLACED
        m = CONVERSION_NAME.fullmatch(name)
        if m is None:
            return None
        if out_format == "yuv":
            return REPLACED if m.group("video") in views else None
        return KEPT if name.startswith("frame_") else None

    return claims


def _other_view_set(folder: Path, n_views: int) -> str | None:
    """How a frame folder of an earlier run differs from this run's view set: None where
    it holds the same views, else e.g. ``"3 x 3 views"``."""
    views = {m.group("view") for p in folder.iterdir()
             if (m := CONVERSION_NAME.fullmatch(p.name)) and m.group("view")}
    if views == set(view_names(n_views)):
        return None
    side = round(len(views) ** 0.5)
    return f"{side} x {side} views" if side * side == len(views) else f"{len(views)} views"


def check_output_folder(out: Path, claims: Callable[[str], str | None], what: str,
                        n_views: int | None = None) -> None:
    """Stop with :class:`ConvertError` where the folder ``out`` holds files of an earlier
    conversion (:data:`CONVERSION_NAME`) that this one, ``what`` (e.g. "3 x 3 views of one
    image"), would neither replace nor keep (``claims``: :data:`REPLACED`, :data:`KEPT` or
    None), or kept frame folders of another view set than this run's ``n_views`` (a
    recording converted in chunks keeps one view set). A folder that does not exist, and
    files of other names, pass."""
    if not out.is_dir():
        return
    stale: list[str] = []
    for p in sorted(out.iterdir(), key=lambda p: p.name):
        if CONVERSION_NAME.fullmatch(p.name) is None:
            continue
        claim = claims(p.name)
        if claim is None:
            stale.append(p.name)
        elif claim == KEPT and n_views is not None and p.is_dir():
            other = _other_view_set(p, n_views)
            if other is not None:
                stale.append(f"{p.name} ({other})")
    if stale:
        shown = ", ".join(stale[:4]) + (f", ... ({len(stale)} in all)" if len(stale) > 4
                                         else "")
        raise ConvertError(
            f"{out}: holds {shown} from an earlier conversion, which this one ({what}) would "
            "not replace, so the folder would mix two conversions: remove them, or give "
            "another folder with -o")


def stale_view_videos(out: Path, written: set[str]) -> list[Path]:
    """The view videos in ``out`` of this run's views (``written``: the names it wrote)
    at another size or bit depth: an earlier run's, which this run's replace."""
    views = {m.group("video") for n in written
             if (m := CONVERSION_NAME.fullmatch(n)) and m.group("video")}
    return sorted(p for p in out.iterdir() if p.name not in written
                  and (m := CONVERSION_NAME.fullmatch(p.name)) and m.group("video") in views)
