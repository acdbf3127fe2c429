"""``reg_b/rig.json``: registration B (Section II-C of the paper), written by rule
``rig_b`` and read by the depth of registration B, the merge (Eq. 6), Table I, the
view synthesis and the ground-truth check.

The N x N views of one camera as pinhole cameras in the central view's frame (metres,
OpenCV axes, ``cam_to_central``), the view model that made them (``exact`` or the
paper's), the scene's depth range and the symbols of Eqs. 1-4 (``symbols``: the
paper's model, ``paper``/``exact``: both models' numbers, ``check``: the inverse check
of Eqs. 2-3). :func:`plenocal.calib.reg_b.rig.build_rig` computes the document.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.versioned import decode
from plenocal.camera import PinholeCamera
from plenocal.io.files import write_json
from plenocal.names import view_key

FORMAT = "plenocal.rig"
VERSION = 1


@dataclass(frozen=True)
class RigB:
    """A ``rig.json`` document with typed access to what its readers use; ``doc`` is the
    whole document (the models' numbers and checks, for the report and the truth)."""

    doc: Mapping

    @property
    def model(self) -> str:
        return str(self.doc["model"])

    @property
    def n_views(self) -> int:
        return int(self.doc["n_views"])

    @property
    def width(self) -> int:
        return int(self.doc["width"])

    @property
    def height(self) -> int:
        return int(self.doc["height"])

    @property
    def focal_px(self) -> float:
        """Registration A's focal length the rig was built with."""
        return float(self.doc["focal_px"])

    @property
    def depth_range_m(self) -> tuple[float, float]:
        near, far = self.doc["depth_range_m"]
        return float(near), float(far)

    @property
    def symbols(self) -> Mapping:
        return self.doc["symbols"]

    def view_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """View -> (K, cam_to_central)."""
        return {k: (np.asarray(v["K"], dtype=float), np.asarray(v["cam_to_central"], dtype=float))
                for k, v in self.doc["views"].items()}

    def cameras(self) -> dict[str, PinholeCamera]:
        """View -> camera in the central view's frame (cam_to_world = cam_to_central)."""
        return {k: PinholeCamera(K, M, self.width, self.height)
                for k, (K, M) in self.view_poses().items()}

    def set_cameras(self, shot: str) -> dict[str, PinholeCamera]:
        """The N x N set of ``shot`` in its central view's frame, keyed ``<shot>/<view>``."""
        return {view_key(shot, k): c for k, c in self.cameras().items()}


def write_rig(path: str | Path, doc: Mapping) -> None:
    """Write a document of :func:`plenocal.calib.reg_b.rig.build_rig` as ``rig.json``."""
    write_json(path, {"format": FORMAT, "version": VERSION, **doc})


def _check(doc: dict, path: str | Path) -> RigB:
    rig = RigB(doc)
    for key in ("model", "n_views", "width", "height", "focal_px", "depth_range_m", "symbols",
                "views"):
        doc[key]  # noqa: B018  (a missing key is reported by decode)
    if len(doc["views"]) != rig.n_views ** 2:
        raise ValueError(f"{path}: {len(doc['views'])} views for n_views = {rig.n_views}; "
                         "rerun rule rig_b")
    return rig


def read_rig(path: str | Path) -> RigB:
    """Read ``rig.json`` (this version only)."""
    return decode(path, FORMAT, VERSION, "rig.json", "run rule rig_b",
                  lambda doc: _check(doc, path))
