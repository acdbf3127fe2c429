"""The code a rule's script runs (plenocal.codehash): the hash of the package modules it
imports, which the workflow gives each script's job as a param, so that a change to the
package reruns the stages that run the changed code, and no others."""

from __future__ import annotations

from pathlib import Path

from plenocal.codehash import PackageCode, installed, script_code

ROOT = Path(__file__).resolve().parents[1]


def _package(tmp_path: Path) -> Path:
    """pkg/{__init__, a, b, c, sub/{__init__, d}}.py: a imports b at the top and c inside a
    function; sub.d imports nothing; e is imported by nobody."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    files = {
        "__init__.py": '"""the package"""\n',
        "a.py": ("import numpy\nfrom pkg.b import thing\n\n\ndef f():\n"
                 "    from pkg import c  # noqa\n"),
        "b.py": "thing = 1\n",
        "c.py": "from pkg.sub import (\n    d,\n)\n",
        "e.py": "x = 2\n",
        "sub/__init__.py": "",
        "sub/d.py": "y = 3\n",
    }
    for name, text in files.items():
        (pkg / name).write_text(text)
    return pkg


def test_the_closure_follows_every_import(tmp_path):
    """Top-level and function-level imports, ``from pkg import module``, parenthesised
    names over lines and the enclosing packages' ``__init__``; a function or class
    imported by name is no module; a module nobody imports is left out."""
    pkg = _package(tmp_path)
    script = tmp_path / "script.py"
    script.write_text("import cv2\nfrom pkg.a import f, g as h\n")
    code = PackageCode(tmp_path, "pkg")
    assert list(code.closure(script)) == ["pkg", "pkg.a", "pkg.b", "pkg.c", "pkg.sub",
                                          "pkg.sub.d"]
    assert "pkg.e" not in code.closure(script) and (pkg / "e.py").is_file()


def test_the_hash_changes_with_the_code_the_script_runs_only(tmp_path):
    pkg = _package(tmp_path)
    script = tmp_path / "script.py"
    script.write_text("from pkg.a import f\n")
    before = PackageCode(tmp_path, "pkg").digest(script)
    assert PackageCode(tmp_path, "pkg").digest(script) == before  # the same sources
    (pkg / "e.py").write_text("x = 3\n")  # imported by nobody
    assert PackageCode(tmp_path, "pkg").digest(script) == before
    (pkg / "sub" / "d.py").write_text("y = 4\n")  # reached through a lazy import
    changed = PackageCode(tmp_path, "pkg").digest(script)
    assert changed != before and len(changed) == 16


def test_each_script_reaches_the_modules_it_runs():
    """Against the installed package: the merge's script reaches Eq. 6's module and not
    the simulator; the refinement's reaches the adjustments."""
    merge = installed().closure(ROOT / "scripts" / "merge.py")
    assert "plenocal.calib.merge" in merge and "plenocal.simulate" not in merge
    assert "plenocal.calib.refine" in installed().closure(ROOT / "scripts" / "refine.py")
    for script in sorted((ROOT / "scripts").glob("*.py")):
        assert len(script_code(script)) == 16
