"""``reg_b/rig.json``: registration B (Section II-C of the paper), written by rule
``rig_b`` and read by the depth of registration B, the merge (Eq. 6), Table I, the
view synthesis and the ground-truth check.

The N x N views of one camera as pinhole cameras in the central view's frame (metres,
OpenCV axes, ``cam_to_central``), the view model that made them (``exact`` or the
paper's), the scene's depth range and the symbols of Eqs. 1-4 (``symbols``: the
paper's model, ``paper``/``exact``: both models' numbers, ``check``: the inverse check
of Eqs. 2-3 of the model used, typed as :class:`InverseCheck`).
:func:`plenocal.calib.reg_b.rig.build_rig` computes the document.
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
REMEDY = "rerun rule rig_b"
#: the verdicts of the inverse check of Eqs. 2-3
#: (:func:`plenocal.calib.reg_b.paper_model.inverse_check`)
VERDICTS = ("pass", "fail", "skipped")


@dataclass(frozen=True)
class InverseCheck:
    """The inverse check of Eqs. 2-3 of the model ``views`` were made with (the ``check``
    of ``rig.json``), as its readers use it: B and alpha from the measured near/far
    distances against the model's. ``verdict``: one of :data:`VERDICTS`; a ``skipped``
    check has its ``reason`` and no figures; a judged one has the relative differences
    of B and of tan(alpha) (None where not finite) and the ``tolerance``."""

    verdict: str
    reason: str = ""
    rel_diff_B: float | None = None
    rel_diff_alpha: float | None = None
    tolerance: float | None = None

    @property
    def failed(self) -> bool:
        return self.verdict == "fail"

    @classmethod
    def from_dict(cls, d: Mapping, path: str | Path, remedy: str = REMEDY) -> InverseCheck:
        """From the ``check`` mapping of ``rig.json`` at ``path``; a missing key or an
        unknown verdict is an error naming the file, the key and ``remedy``."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{path}: key 'check' is a {type(d).__name__}, not the inverse "
                             f"check of Eqs. 2-3; {remedy}")

        def get(key: str):
            if key not in d:
                raise ValueError(f"{path}: the inverse check of Eqs. 2-3 has no key "
                                 f"'check.{key}'; {remedy}")
            return d[key]

        verdict = get("verdict")
        if verdict not in VERDICTS:
            raise ValueError(f"{path}: key 'check.verdict' = {verdict!r} is not one of "
                             f"{', '.join(VERDICTS)}; {remedy}")
        if verdict == "skipped":
            return cls(verdict, reason=str(get("reason")))

        def num(key: str) -> float | None:
            v = get(key)
            return None if v is None else float(v)

        return cls(verdict, rel_diff_B=num("rel_diff_B"), rel_diff_alpha=num("rel_diff_alpha"),
                   tolerance=float(get("tolerance")))


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

    @property
    def check(self) -> InverseCheck:
        """The inverse check of Eqs. 2-3 of the model the views were made with (checked
        when the file was read)."""
        return InverseCheck.from_dict(self.doc["check"], "rig.json")

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
    """Write a document of :func:`plenocal.calib.reg_b.rig.build_rig` as ``rig.json``,
    checked as :func:`read_rig` checks it: a key the readers need that the producer
    left out or renamed is an error here, not a file that fails later."""
    out = {"format": FORMAT, "version": VERSION, **doc}
    producer = ("the producer (plenocal.calib.reg_b.rig.build_rig) must write what "
                "plenocal.artifacts.rig reads")
    try:
        _check(out, path, producer)
    except KeyError as err:
        raise ValueError(f"{path}: rig.json would lack key {err}; {producer}") from None
    write_json(path, out)


def _check(doc: dict, path: str | Path, remedy: str = REMEDY) -> RigB:
    rig = RigB(doc)
    for key in ("model", "n_views", "width", "height", "focal_px", "depth_range_m", "symbols",
                "views"):
        doc[key]  # noqa: B018  (a missing key is reported by decode)
    if len(doc["views"]) != rig.n_views ** 2:
        raise ValueError(f"{path}: {len(doc['views'])} views for n_views = {rig.n_views}; "
                         f"{remedy}")
    InverseCheck.from_dict(doc["check"], path, remedy)
    return rig


def read_rig(path: str | Path) -> RigB:
    """Read ``rig.json`` (this version only)."""
    return decode(path, FORMAT, VERSION, "rig.json", "run rule rig_b",
                  lambda doc: _check(doc, path))
