"""Shot folders that a dataset's config no longer names.

A shot taken out of a dataset (or an array made smaller) leaves its folders behind: its
converted views in ``results/<dataset>/views/<shot>/``, the depth maps of its views in
``depth/views/<shot>/`` and, on a synthetic dataset, its true depth maps and ideal renders
in ``ground_truth/depth/<shot>/`` and ``ground_truth/renders/<shot>/``
(:data:`SHOT_FOLDERS`). Snakemake deletes no output it no longer plans, and nothing of the
workflow reads them (every rule asks for the config's shots by name). A user who points a
tool at ``views/`` (COLMAP, a NeRF) or at the depth maps (TMIV, RVS) would take them for
this calibration's, so the workflow names them at its start (``onstart`` in the
Snakefile), with the command that removes them; it removes nothing itself.
"""

from __future__ import annotations

import shlex
from collections.abc import Iterable
from pathlib import Path

from plenocal.names import is_shot

#: the folders of ``results/<dataset>/`` that hold one folder per shot
SHOT_FOLDERS = ("views", "depth/views", "ground_truth/depth", "ground_truth/renders")


def stale_shot_folders(folder: str | Path, shots: Iterable[str]) -> list[Path]:
    """The folders under ``folder`` (one of a dataset's :data:`SHOT_FOLDERS`, e.g.
    ``results/<dataset>/views``) named as shots (:func:`plenocal.names.is_shot`) that are
    not among ``shots``, sorted; none where the folder does not exist. Other entries
    (``convert_setup.json``, a user's own folders) are left out."""
    base = Path(folder)
    if not base.is_dir():
        return []
    known = set(shots)
    return sorted(p for p in base.iterdir()
                  if p.is_dir() and is_shot(p.name) and p.name not in known)


def stale_dataset_folders(dataset_dir: str | Path, shots: Iterable[str]) -> list[Path]:
    """:func:`stale_shot_folders` of each of :data:`SHOT_FOLDERS` under ``dataset_dir``
    (``results/<dataset>``), in that order."""
    known = set(shots)  # read once: ``shots`` may be an iterator
    return [p for sub in SHOT_FOLDERS for p in stale_shot_folders(Path(dataset_dir, sub), known)]


def stale_shot_message(dataset: str, folders: list[Path]) -> str:
    """The warning for ``folders`` of ``dataset`` (:func:`stale_dataset_folders`): the
    shots, where their folders are, that nothing reads them, and the command that removes
    them."""
    names = ", ".join(sorted({p.name for p in folders}))
    where = ", ".join(dict.fromkeys(f"{p.parent}/" for p in folders))
    remove = "rm -r " + " ".join(shlex.quote(str(p)) for p in folders)
    return (f"dataset {dataset}: {len(folders)} shot folder(s) that the config no longer "
            f"names ({names}) under {where}: outputs of an earlier run, which this "
            f"calibration neither reads nor describes; remove them so that no tool pointed "
            f"at these folders takes them for this calibration's: {remove}")
