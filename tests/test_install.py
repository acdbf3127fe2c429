"""What the README's plain install (``pip install -e .``, no extras) brings: everything
Snakemake's own report (``snakemake --report report.zip``) imports. The test extra hides a
gap here (pytest brings pygments), so the check reads the dependency lists instead of
trying the imports: every package that a module of ``snakemake.report`` imports must be
required by pyproject.toml's main dependencies, directly or through their own
requirements (with the extras they name)."""

from __future__ import annotations

import ast
import importlib.metadata as md
import importlib.util
import re
import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def report_imports() -> set[str]:
    """Top-level modules imported anywhere in snakemake.report (at module level or inside
    functions, as the report's optional imports are), other than the standard library and
    snakemake itself."""
    spec = importlib.util.find_spec("snakemake.report")
    assert spec is not None and spec.submodule_search_locations
    mods = set()
    for folder in spec.submodule_search_locations:
        for path in Path(folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    mods.update(a.name.split(".")[0] for a in node.names)
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    mods.add(node.module.split(".")[0])
    return {m for m in mods if m not in sys.stdlib_module_names and m != "snakemake"}


def install_closure(requirements: list[str]) -> set[str]:
    """The distributions that ``pip install`` of ``requirements`` brings: each one's
    requirements, followed through installed metadata, with the markers evaluated for
    this interpreter and the extras asked for."""
    seen: set[str] = set()
    todo = [(Requirement(r), frozenset()) for r in requirements]
    asked: set[tuple[str, frozenset]] = set()
    while todo:
        req, parent_extras = todo.pop()
        if req.marker is not None and not any(
            req.marker.evaluate({"extra": e}) for e in (parent_extras or {""})
        ):
            continue
        name = _norm(req.name)
        key = (name, frozenset(req.extras))
        if key in asked:
            continue
        asked.add(key)
        seen.add(name)
        for sub in md.requires(req.name) or []:
            todo.append((Requirement(sub), frozenset(req.extras)))
    return seen


def test_plain_install_brings_what_snakemake_report_imports():
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    brought = install_closure(deps)
    by_module = md.packages_distributions()
    needed = {}
    for mod in sorted(report_imports()):
        dists = by_module.get(mod)
        assert dists, f"snakemake.report imports {mod!r}, which no installed distribution gives"
        needed[mod] = {_norm(d) for d in dists}
    # what the report's own error names when it is missing (the failure)
    assert "pygments" in needed, sorted(needed)
    missing = {m: sorted(d) for m, d in needed.items() if not d & brought}
    assert not missing, (
        f"snakemake --report imports {missing}, which pyproject.toml's dependencies "
        "do not bring (snakemake's 'reports' extra)"
    )
