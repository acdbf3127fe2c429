"""The plain camera file of DESIGN.md (``cameras.json``), shared by ground truth and
every calibration: ``{"units": "m", "cameras": {"<cam>/<view>": {"K", "cam_to_world",
"width", "height"}}}`` in OpenCV axes with pixel centres at integers."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from plenocal.camera import PinholeCamera, read_cameras, write_cameras


def write_plain(path: str | Path, cameras: Mapping[str, PinholeCamera],
                extra: dict | None = None) -> None:
    """Write ``cameras.json`` (metres); ``extra`` adds top-level keys (provenance)."""
    for name in cameras:
        if name.count("/") != 1:
            raise ValueError(f"camera name {name!r} must be '<cam>/<view>'")
    write_cameras(path, dict(cameras), units="m", extra=extra)


def read_plain(path: str | Path) -> dict[str, PinholeCamera]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: cameras.json not found")
    return read_cameras(path)
