"""``reg_a/reg_a.json``: registration A (Section II-B of the paper), written by rule
``map_a`` and read by registration B (the focal length), the depth of registration A,
the scale (Eq. 5), the merge (Eq. 6), the naive baseline and Table I.

The central view of every shot as a pinhole camera in SfM units (one shared
SIMPLE_PINHOLE camera: every ``K`` is the same), camera-to-world in OpenCV axes, plus
the reconstruction's statistics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from plenocal.artifacts.versioned import decode
from plenocal.camera import PinholeCamera
from plenocal.io.files import write_json

FORMAT = "plenocal.reg_a"
VERSION = 1


@dataclass(frozen=True)
class RegistrationA:
    """Registration A: ``cameras`` maps each shot to its central view's camera."""

    focal_px: float
    width: int
    height: int
    mapper: str  # COLMAP's incremental or global mapper
    cameras: dict[str, PinholeCamera]
    stats: dict = field(default_factory=dict)  # points, observations, errors (px)
    units: str = "sfm"

    @property
    def poses(self) -> dict[str, np.ndarray]:
        """Shot -> 4x4 camera-to-world of its central view (SfM units)."""
        return {k: c.cam_to_world for k, c in self.cameras.items()}

    def to_dict(self) -> dict:
        return {
            "format": FORMAT, "version": VERSION, "units": self.units, "mapper": self.mapper,
            "focal_px": float(self.focal_px), "width": int(self.width),
            "height": int(self.height),
            "cameras": {k: {"K": c.K, "cam_to_world": c.cam_to_world}
                        for k, c in sorted(self.cameras.items())},
            **self.stats,
        }


def write_reg_a(path: str | Path, reg: RegistrationA) -> None:
    write_json(path, reg.to_dict())


_FIELDS = {"format", "version", "units", "mapper", "focal_px", "width", "height", "cameras"}


def read_reg_a(path: str | Path) -> RegistrationA:
    """Read ``reg_a.json`` (this version only)."""
    return decode(path, FORMAT, VERSION, "reg_a.json", "run registration A (rule map_a)",
                  lambda doc: _registration(doc, path))


def _registration(doc: dict, path: str | Path) -> RegistrationA:
    W, H = int(doc["width"]), int(doc["height"])
    cams = {}
    for k, d in doc["cameras"].items():
        M = np.asarray(d["cam_to_world"], dtype=float)
        K = np.asarray(d["K"], dtype=float)
        if M.shape != (4, 4) or K.shape != (3, 3):
            raise ValueError(f"{path}: camera {k}: K must be 3x3 and cam_to_world 4x4")
        cams[k] = PinholeCamera(K, M, W, H)
    if not cams:
        raise ValueError(f"{path}: registration A holds no camera; rerun rule map_a")
    return RegistrationA(
        focal_px=float(doc["focal_px"]), width=W, height=H, mapper=str(doc["mapper"]),
        cameras=cams, stats={k: v for k, v in doc.items() if k not in _FIELDS},
        units=str(doc["units"]))
