"""The views' grey levels as the joint refinement's alignment reads them
(:mod:`plenocal.calib.track_alignment`), decoded once per refinement.

With ``refine.tracks: both`` the central views' points (:mod:`plenocal.calib.central_tracks`)
and every view's own matches (:func:`plenocal.calib.track_sets.aligned_keypoints`) are aligned
on the same views one after the other, and each view was decoded for each: on the default
dataset 700 PNGs twice, about 4.5 s of the refine job's 90. :class:`ViewGreys` keeps what
it decoded while it lives (the two alignments, not the adjustments after them).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np


def read_grey(path: str | Path) -> np.ndarray:
    """The image at ``path`` in grey levels (8 or 16 bits, as stored)."""
    import cv2  # noqa: PLC0415

    grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH)
    if grey is None:
        raise ValueError(f"{path}: not a readable image (rule refine aligns its observations "
                         "on the views): rerun the conversion")
    return grey


class ViewGreys(Mapping):
    """View key (``<shot>/<view>``) -> its image file, as the refinement's ``images``
    mapping, whose grey levels :meth:`grey` decodes once and keeps (every entry is
    decoded on its own: the same arrays on any threads)."""

    def __init__(self, files: Mapping[str, str | Path]) -> None:
        self._files = dict(files)
        self._greys: dict[str, np.ndarray] = {}

    def __getitem__(self, key: str) -> str | Path:
        return self._files[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._files)

    def __len__(self) -> int:
        return len(self._files)

    def grey(self, key: str) -> np.ndarray:
        """View ``key``'s grey levels, decoded the first time only."""
        out = self._greys.get(key)
        if out is None:
            out = self._greys[key] = read_grey(self._files[key])
        return out


def grey_of(images: Mapping[str, str | Path], key: str) -> np.ndarray:
    """View ``key``'s grey levels from ``images`` (a :class:`ViewGreys` keeps them; any
    other mapping of files is read each time)."""
    return images.grey(key) if isinstance(images, ViewGreys) else read_grey(images[key])
