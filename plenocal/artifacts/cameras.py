"""``cameras.json``: the plain camera file of DESIGN.md, one for every calibration
(``calibration/cameras.json``, the naive baseline's ``baseline/cameras.json``) and for
the ground truth (``ground_truth/cameras.json``); read by the depth maps for synthesis,
the synthesis experiments, Table I, gt_errors and the report.

``{"format": "plenocal.cameras", "version": 1, "units": "m" | "sfm", "cameras":
{"<cam>/<view>": {"K": 3x3, "cam_to_world": 4x4, "width": W, "height": H}}, ...}``:
OpenCV axes, camera-to-world poses, pixel centres at integers; further top-level keys
are the writer's provenance (e.g. ``fit_residual_px`` of the ground truth). DESIGN.md's
layout with the format name and version that every artifact carries (issue 16): a file
of another version, an unknown unit or a camera without one of its keys is refused
with the file and the remedy.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from plenocal.artifacts.versioned import decode
from plenocal.camera import PinholeCamera, check_cameras
from plenocal.io.files import write_json
from plenocal.names import split_key

FORMAT = "plenocal.cameras"
VERSION = 1
#: metres (every metric calibration, the ground truth) or SfM units (the naive baseline)
UNITS = ("m", "sfm")
NAME = "camera file (cameras.json)"
REMEDY = "rerun the rule that wrote it (merge, baseline_sfm or ground_truth)"
_RESERVED = ("format", "version", "units", "cameras")


def write_cameras(path: str | Path, cameras: Mapping[str, PinholeCamera], units: str = "m",
                  extra: Mapping | None = None) -> None:
    """Write ``cameras`` (``"<cam>/<view>"`` -> camera) in ``units``; ``extra`` adds
    top-level provenance keys."""
    if units not in UNITS:
        raise ValueError(f"{path}: units {units!r}: use one of {', '.join(UNITS)}")
    for name in cameras:
        split_key(name)  # "<cam>/<view>" or a ValueError naming it
    check_cameras(cameras, str(path), skew=True)
    clash = sorted(set(extra or ()) & set(_RESERVED))
    if clash:
        raise ValueError(f"{path}: provenance keys {clash} would overwrite the file's own")
    doc = {"format": FORMAT, "version": VERSION, "units": units,
           "cameras": {k: cameras[k].to_dict() for k in sorted(cameras)}}
    doc.update(dict(extra or {}))
    write_json(path, doc)


def read_camera_units(path: str | Path) -> str:
    """The units of a camera file (this version only)."""
    return decode(path, FORMAT, VERSION, NAME, REMEDY, lambda doc: _units(doc, path))


def read_cameras(path: str | Path) -> dict[str, PinholeCamera]:
    """The cameras of a camera file (this version only), by ``"<cam>/<view>"``."""
    def build(doc: dict) -> dict[str, PinholeCamera]:
        _units(doc, path)
        entries = doc["cameras"]
        if not isinstance(entries, Mapping) or not entries:
            raise ValueError(f"{path}: key 'cameras' holds {_what(entries)}: expected a "
                             f"mapping of '<cam>/<view>' to cameras; {REMEDY}")
        cams = {}
        for key, entry in entries.items():
            try:
                split_key(key)
                cams[key] = _camera(entry)
            except (TypeError, ValueError, AttributeError) as err:
                raise ValueError(f"{path}: camera {key!r} (key 'cameras'): {err}; "
                                 f"{REMEDY}") from None
        check_cameras(cams, str(path), REMEDY, skew=True)
        return cams

    return decode(path, FORMAT, VERSION, NAME, REMEDY, build)


def _what(value: object) -> str:
    return "an empty mapping" if isinstance(value, Mapping) else f"a {type(value).__name__}"


def _camera(entry: object) -> PinholeCamera:
    """One camera of the file, its image size a whole number of pixels (``int()`` would
    take 310.7 as 310 without a word) and its matrices numbers."""
    if not isinstance(entry, Mapping):
        raise ValueError(f"{_what(entry)}, not a mapping of K, cam_to_world, width, height")
    missing = [k for k in ("K", "cam_to_world", "width", "height") if k not in entry]
    if missing:
        raise ValueError(f"without key(s) {', '.join(repr(k) for k in missing)}")
    for side in ("width", "height"):
        size = entry[side]
        if isinstance(size, bool) or not (isinstance(size, int) or (
                isinstance(size, float) and size.is_integer())):
            raise ValueError(f"{side} {size!r}: a whole number of pixels")
    return PinholeCamera.from_dict(entry)


def _units(doc: dict, path: str | Path) -> str:
    units = doc["units"]
    if units not in UNITS:
        raise ValueError(f"{path}: units {units!r} (key 'units'): use one of "
                         f"{', '.join(UNITS)}; {REMEDY}")
    return units
