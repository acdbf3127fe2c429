"""The frame every artifact file shares: a format name and a version, checked on reading."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from plenocal.io.files import read_json


def read_versioned(path: str | Path, fmt: str, version: int, name: str, remedy: str) -> dict:
    """The JSON document at ``path`` if it says ``format: fmt`` and ``version``; otherwise
    an error naming the file, what it is and ``remedy`` (e.g. "rerun rule scale")."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: {name} not found; {remedy}")
    return check_versioned(path, read_json(path), fmt, version, name, remedy)


def check_versioned(path: str | Path, doc: Any, fmt: str, version: int, name: str,
                    remedy: str) -> dict:
    """``doc`` (read from ``path``) if it is a mapping that says ``format: fmt`` and
    ``version``; otherwise the error of :func:`read_versioned`."""
    if not isinstance(doc, dict) or doc.get("format") != fmt or doc.get("version") != version:
        got = (doc.get("format"), doc.get("version")) if isinstance(doc, dict) else (None, None)
        raise ValueError(f"{path}: not a {name} of version {version} (format {got[0]!r}, "
                         f"version {got[1]!r}); {remedy}")
    return doc


@contextmanager
def complete(path: str | Path, name: str, version: int, remedy: str):
    """Turn a missing key while decoding a checked document into an error naming it."""
    try:
        yield
    except KeyError as err:
        raise ValueError(f"{path}: {name} version {version} without key {err}; the file is "
                         f"damaged: {remedy}") from None


def decode(path: str | Path, fmt: str, version: int, name: str, remedy: str,
           build: Callable[[dict], Any]) -> Any:
    """:func:`read_versioned`, then ``build(doc)`` with missing keys reported."""
    doc = read_versioned(path, fmt, version, name, remedy)
    with complete(path, name, version, remedy):
        return build(doc)
