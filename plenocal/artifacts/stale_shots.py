"""Shot folders that a dataset's config no longer names.

A shot taken out of a dataset (or an array made smaller) leaves its converted views in
``results/<dataset>/views/<shot>/``: Snakemake deletes no output it no longer plans, and
nothing of the workflow reads them (every rule asks for the config's shots by name). A
user who points a tool at ``views/`` would take them for views of this calibration, so
the workflow names them at its start (``onstart`` in the Snakefile), with the command that
removes them; it removes nothing itself.
"""

from __future__ import annotations

import shlex
from collections.abc import Iterable
from pathlib import Path

from plenocal.names import is_shot


def stale_shot_folders(views_dir: str | Path, shots: Iterable[str]) -> list[Path]:
    """The folders under ``views_dir`` (a dataset's ``results/<dataset>/views``) named as
    shots (:func:`plenocal.names.is_shot`) that are not among ``shots``, sorted; none where
    the folder does not exist. Other entries (``convert_setup.json``, a user's own
    folders) are left out."""
    base = Path(views_dir)
    if not base.is_dir():
        return []
    known = set(shots)
    return sorted(p for p in base.iterdir()
                  if p.is_dir() and is_shot(p.name) and p.name not in known)


def stale_shot_message(dataset: str, folders: list[Path]) -> str:
    """The warning for ``folders`` of ``dataset`` (:func:`stale_shot_folders`): what they
    are, that nothing reads them, and the command that removes them."""
    names = ", ".join(p.name for p in folders)
    remove = "rm -r " + " ".join(shlex.quote(str(p)) for p in folders)
    return (f"dataset {dataset}: {len(folders)} shot folder(s) under "
            f"{folders[0].parent}/ that the config no longer names ({names}): views of an "
            f"earlier run, which this calibration neither reads nor describes; remove "
            f"them so that no tool pointed at views/ takes them for its views: {remove}")
