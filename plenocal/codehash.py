"""The code a rule's script runs: the hash of every module of the package it imports, so
that a change to the package's code reruns the stages that run it and no others.

Snakemake reruns a job whose script changed (its ``code`` trigger), but the logic lives
in this package, which it does not look into: an upgrade that changed, say, Eq. 5 left
every ``merge/scale.json`` as the old code wrote it. The workflow gives each rule with a
script the hash of that script's import closure in the package as a param
(``rules/common.smk``: ``code_params``), so Snakemake's ``params`` trigger reruns the
job when a module the job imports changed.

The closure is read from the sources' import statements (``import plenocal.x``, ``from
plenocal.x import y``, where ``y`` may itself be a module; imports inside functions
count, so it errs towards rerunning), with every enclosing package's ``__init__.py``. A
regular expression reads them, not :mod:`ast`: the whole package in about 20 ms instead
of 0.7 s, which every Snakemake invocation, the no-op included, pays.
"""

from __future__ import annotations

import functools
import hashlib
import re
from pathlib import Path

#: ``import a.b`` or ``from a.b import c, d as e`` / ``from a.b import (c,\n d)`` at the
#: start of a line (indented: inside a function), ``{name}`` the top-level package
_IMPORT = (r"^[ \t]*(?:from[ \t]+({name}(?:\.\w+)*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]+)"
           r"|import[ \t]+({name}(?:\.\w+)*))")
#: the hash's length in hex digits (a param Snakemake records and compares)
DIGITS = 16


class PackageCode:
    """The modules of the package ``root / name`` (a folder with ``__init__.py``) and
    their imports, each source read once."""

    def __init__(self, root: str | Path, name: str) -> None:
        self.root, self.name = Path(root), name
        self._pattern = re.compile(_IMPORT.format(name=re.escape(name)).encode(), re.M)
        # module -> its source, found once (a dict lookup per imported name, no stat)
        self.files: dict[str, Path] = {}
        for path in (self.root / name).rglob("*.py"):
            parts = path.relative_to(self.root).with_suffix("").parts
            self.files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
        self._read: dict[Path, tuple[str, frozenset[str]]] = {}

    def _source(self, path: Path) -> tuple[str, frozenset[str]]:
        """(sha1 of the file, the package's modules it imports), each file read once."""
        if path not in self._read:
            src = path.read_bytes()
            self._read[path] = hashlib.sha1(src).hexdigest(), frozenset(self.imports(src))
        return self._read[path]

    def imports(self, source: bytes) -> set[str]:
        """The package's modules that ``source`` imports, with their enclosing packages."""
        found = set()
        for m in self._pattern.finditer(source):
            if m.group(3):
                found.add(m.group(3).decode())
                continue
            module = m.group(1).decode()
            found.add(module)
            for name in re.findall(r"(\w+)(?:\s+as\s+\w+)?", m.group(2).decode()):
                sub = f"{module}.{name}"
                if sub in self.files:
                    found.add(sub)
        out = set()
        for module in found:
            parts = module.split(".")
            out.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
        return out

    def closure(self, script: str | Path) -> dict[str, str]:
        """Module -> sha1 of its source, for every module of the package that ``script``
        imports directly or through others."""
        todo = list(self.imports(Path(script).read_bytes()))
        out: dict[str, str] = {}
        while todo:
            module = todo.pop()
            if module in out:
                continue
            path = self.files.get(module)
            if path is None:
                out[module] = ""  # a name the regex took for a module: none such
                continue
            digest, deps = self._source(path)
            out[module] = digest
            todo.extend(deps - out.keys())
        return {k: v for k, v in sorted(out.items()) if v}

    def digest(self, script: str | Path) -> str:
        """One hash of :meth:`closure`: it changes where a module ``script`` runs changed,
        was added to its imports or left them."""
        h = hashlib.sha1()
        for module, digest in self.closure(script).items():
            h.update(f"{module} {digest}\n".encode())
        return h.hexdigest()[:DIGITS]


@functools.cache
def installed() -> PackageCode:
    """This package as it is installed (its sources where Python imports it from)."""
    here = Path(__file__).resolve().parent
    return PackageCode(here.parent, here.name)


def script_code(script: str | Path) -> str:
    """:meth:`PackageCode.digest` of ``script`` against the installed package."""
    return installed().digest(script)
