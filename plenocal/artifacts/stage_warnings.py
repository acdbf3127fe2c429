"""The ``warnings`` list that a stage writes into its output so that what its log warns
about reaches the report's first screen (issue 16).

One shape for every producer: the key ``warnings``, a list of non-empty strings, one
message each. The producers write it with :func:`warning_list` (``convert_setup.json``,
``views/<shot>/disparity.json``, ``reg_a/features.json``); the readers take it with
:func:`warnings_of` inside their typed reader, or with :func:`read_warnings` for a file
whose only reader is the report (``features.json``). Another shape - a single string,
mappings ``{"message": ...}``, a missing key - is refused with the file, the key and the
remedy, never guessed at.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from plenocal.io.files import read_json

#: the key every producer writes its messages under
WARNINGS_KEY = "warnings"


def warning_list(messages: Iterable[str]) -> list[str]:
    """``messages`` as written under :data:`WARNINGS_KEY`: a list of non-empty strings.
    Anything else is a producer's bug, refused before it reaches a file."""
    out = list(messages)
    for i, m in enumerate(out):
        if not isinstance(m, str) or not m.strip():
            raise TypeError(f"{WARNINGS_KEY}[{i}] = {m!r}: a stage's warnings are non-empty "
                            "strings (plenocal.artifacts.stage_warnings)")
    return out


def warnings_of(doc: Mapping, path: str | Path, remedy: str) -> tuple[str, ...]:
    """The messages under :data:`WARNINGS_KEY` of the document read from ``path``; a
    missing key or another shape is an error naming ``path``, the key and ``remedy``."""
    key = WARNINGS_KEY
    if key not in doc:
        raise ValueError(f"{path}: no key {key!r} (a list of messages); {remedy}")
    raw = doc[key]
    if not isinstance(raw, list):
        raise ValueError(f"{path}: key {key!r} is a {type(raw).__name__}, not a list of "
                         f"messages; {remedy}")
    for i, m in enumerate(raw):
        if not isinstance(m, str) or not m.strip():
            raise ValueError(f"{path}: key {key!r}, entry {i} = {m!r} is not a message (a "
                             f"non-empty string); {remedy}")
    return tuple(raw)


def read_warnings(path: str | Path, name: str, remedy: str) -> tuple[str, ...]:
    """The messages of the JSON file ``path`` (``name``: what it is), for a file whose only
    reader is the report."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: {name} not found; {remedy}")
    doc = read_json(path)
    if not isinstance(doc, Mapping):
        raise ValueError(f"{path}: {name} is not a JSON object; {remedy}")
    return warnings_of(doc, path, remedy)
