"""``analysis.npz``: what the conversion of one shot measured in its lenslet image - the
MLA kind, every lens's patch size (:class:`plenocal.convert.patchsize.PatchSizeResult`)
and the micro images' vignetting profiles - so that its views can be rendered in another
job without measuring again.

Rule ``convert`` measures a shot and renders its central view, the one registration A
needs; rule ``convert_views`` renders the other views from this file. Measuring is most
of a conversion (0.64 of 1.0 s a shot on the default camera), so registration A starts
as soon as every shot is measured, and the other views are rendered on the core that
registration A's one-core chain leaves free (issue 15). The views are the same bits
either way: the renderer reads the same numbers (float arrays stored as they are).

The file is an uncompressed ``.npz`` of plain arrays (no pickles) with a ``meta`` entry,
a JSON string carrying the format name and version; a file of another version is refused
with the remedy (convert the shot again).
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocal.artifacts.versioned import check_versioned
from plenocal.convert.errors import ConvertError
from plenocal.convert.patchsize import PatchSizeResult
from plenocal.io.files import atomic_write_bytes, read_npz

FORMAT = "plenocal.convert_analysis"
VERSION = 1
_PATCH_ARRAYS = ("patch", "raw", "confidence", "confident", "lo", "hi", "candidates", "focus")
_REMEDY = "rerun rule convert for this shot (or delete the file)"


@dataclass(frozen=True)
class ConvertAnalysis:
    """One shot's measurements (:class:`plenocal.convert.shot.ShotConversion` makes them
    from the image or takes them from here).

    ``profile`` (T, bins) and ``profile_row`` (n,): the vignetting profiles of
    :func:`plenocal.convert.vignetting.lens_type_profiles`, None without devignetting."""

    mla: str
    mla_scores: dict | None
    patch: PatchSizeResult
    profile: np.ndarray | None
    profile_row: np.ndarray | None

    @property
    def lenses(self) -> int:
        return int(len(self.patch.patch))


def write_analysis(path: str | Path, analysis: ConvertAnalysis) -> None:
    """Write ``analysis`` to ``path`` (deterministic bytes, atomically)."""
    meta = {"format": FORMAT, "version": VERSION, "mla": analysis.mla,
            "mla_scores": analysis.mla_scores, "warnings": list(analysis.patch.warnings),
            "devignette": analysis.profile is not None}
    arrays = {name: np.asarray(getattr(analysis.patch, name)) for name in _PATCH_ARRAYS}
    if analysis.profile is not None:
        arrays["profile"] = np.asarray(analysis.profile)
        arrays["profile_row"] = np.asarray(analysis.profile_row)
    arrays["meta"] = np.array(json.dumps(meta, sort_keys=True))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def read_analysis(path: str | Path) -> ConvertAnalysis:
    """Read what :func:`write_analysis` wrote (this version only); errors name the file
    and the remedy."""
    path = Path(path)
    if not path.is_file():
        raise ConvertError(f"{path}: conversion analysis not found; {_REMEDY}")
    try:
        arrays = read_npz(path)
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError) as exc:
        raise ConvertError(f"{path}: not a readable conversion analysis ({exc}); {_REMEDY}") \
            from None
    try:
        check_versioned(path, meta, FORMAT, VERSION, "conversion analysis", _REMEDY)
    except ValueError as exc:
        raise ConvertError(str(exc)) from None
    missing = [k for k in _PATCH_ARRAYS if k not in arrays]
    if meta.get("devignette"):
        missing += [k for k in ("profile", "profile_row") if k not in arrays]
    if missing or "mla" not in meta:
        raise ConvertError(f"{path}: conversion analysis without {missing or ['mla']}; the "
                           f"file is damaged: {_REMEDY}")
    patch = PatchSizeResult(**{k: arrays[k] for k in _PATCH_ARRAYS},
                            warnings=list(meta.get("warnings", [])))
    return ConvertAnalysis(str(meta["mla"]), meta.get("mla_scores"), patch,
                           arrays.get("profile"), arrays.get("profile_row"))
